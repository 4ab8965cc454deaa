// qpr viewer — recorded handle motion (JSON): which handles, and their
// transform at every recorded frame, so a drag session can be replayed;
// and its replay into a session (handles_from_motion, apply_motion_frame).
//
//   {"format": "qpr-handle-motion", "version": 1, "vertex_count": n,
//    "handles": [{"name": "h0", "vertices": [12, 13, …]} | {"name": "patch 1", "patch": 1}, …],
//    "frames": [[T_0, T_1, …], …]}      T_h: 16 numbers, a 4 × 4 matrix row by row
//
// A point handle is rebuilt from its vertices exactly as when it was made
// (Session::add_handle), a patch handle must name a patch of the model.
#pragma once

#include "session.h"

#include <string>
#include <vector>

namespace qpr::viewer {

struct HandleMotion {
  struct Handle {
    std::string name;
    std::vector<int> vertices;  // a point handle (empty for a patch)
    int patch = -1;
  };
  Eigen::Index vertex_count = 0;
  std::vector<Handle> handles;
  std::vector<std::vector<Eigen::Matrix4d>> frames;  // frames × handles
};

// Appends the current transforms of `handles` as one frame; the handle list
// is taken from the first frame recorded.
void record_frame(const std::vector<ViewHandle>& handles, Eigen::Index vertex_count, HandleMotion* motion);
// Throws std::runtime_error naming the file and the JSON pointer of a bad value.
void write_motion(const std::string& path, const HandleMotion& motion);
HandleMotion read_motion(const std::string& path);

// Poses the session's handles as in recorded frame f (the last one past the
// end); the recorded handles must be the session's handles.
void apply_motion_frame(const HandleMotion& motion, size_t f, Session* session);

// Replaces the session's handles by the recorded ones and poses frame 0.
// Throws std::runtime_error when the recording does not fit the mesh or scene.
void handles_from_motion(const HandleMotion& motion, Session* session);

}  // namespace qpr::viewer
