// qpr viewer — what the headless and the interactive views share: vertex
// colours of the categorical modes, handle markers, camera framing, and the
// replay of a recorded handle motion into a session.
#pragma once

#include "camera.h"
#include "motion.h"
#include "renderer.h"
#include "session.h"
#include "viewer.h"

#include <vector>

namespace qpr::viewer {

// Per-vertex colours of a categorical mode (the deviation mode is coloured in
// the shader): rotational clusters, linear proxies (groups, or the nearest
// sample), affine patches; grey elsewhere. n entries.
std::vector<Eigen::Vector3f> vertex_colors(ColorMode mode, const Session& session);

// The vertices of every handle of the session, for the handle markers.
std::vector<unsigned> handle_markers(const Session& session);

// Frames the rest pose V (n × 3) and, when given, the deformed one, from the
// options' up axis, direction and zoom.
void set_camera(Camera* camera, const qpreduce::deform::Vertices& V, const ViewerOptions& o,
                const qpreduce::deform::Vertices* deformed = nullptr);

// Poses the session's handles as in recorded frame f (the last one past the
// end); the recorded handles must be the session's handles.
void apply_motion_frame(const HandleMotion& motion, size_t f, Session* session);

// Replaces the session's handles by the recorded ones and poses frame 0.
// Throws std::runtime_error when the recording does not fit the mesh or scene.
void handles_from_motion(const HandleMotion& motion, Session* session);

}  // namespace qpr::viewer
