// qpr viewer — `qpr view`: the interactive deformation viewer, and its
// headless mode (render the scenario's last frame to a PNG and exit).
#pragma once

#include "renderer.h"
#include "session.h"

#include <functional>
#include <optional>
#include <string>

namespace qpr::viewer {

struct ViewerOptions {
  // Headless when set: run every scenario frame, write this PNG, exit.
  std::string screenshot;
  int width = 1280, height = 800;
  int samples = 4;  // MSAA samples of the scene framebuffer
  Reconstruction reconstruction = Reconstruction::Gpu;  // falls back to CPU when the basis does not fit
  ColorMode color = ColorMode::Clusters;
  int up_axis = 1;                 // world axis shown upwards (0 x, 1 y, 2 z)
  float yaw_deg = 0.0f, pitch_deg = 15.0f;  // camera direction around the up axis
  float zoom = 0.0f;               // wheel steps (> 0 closer)
  float deviation_scale = 0.1f;    // of the bbox diagonal: the top of the deviation ramp
  bool show_handles = true;
  std::string out_mesh;            // headless: the last pose is also written here
  std::string stats_json;          // headless: timings, path and GPU/CPU agreement
  std::string replay;              // a recorded handle motion (JSON) to play
  int max_frames = 0;              // interactive: close after this many frames (0: never; for smoke tests);
                                   // with a replay, counted from the end of the precompute
  std::string window_screenshot;   // interactive with max_frames: the whole window (panels too) at the last frame
  // Interactive: a JSON log of every displayed frame, written when the window
  // closes: its start and length, whether a handle moved, whether the
  // deformer stepped or the refined pose was shown, and the refine's events
  // (start, shown, cancel with the time cancel() took and the worker's state
  // then). What the window test and docs/performance.md read.
  std::string window_log;
  // Full-space refine (refine_worker.h). Headless, when set: refine the last
  // frame's pose, draw and write the refined pose, report it under "refine".
  // Interactive: the settings of the automatic refine (defaults when unset).
  std::optional<qpreduce::deform::RefineOptions> refine;
  // Interactive: how long the handles must stay still before a refine starts
  // (long enough not to start one between the events of a slow drag).
  double refine_after_still_s = 0.3;
};

// Writes a pose of the input mesh (surfaces OBJ/OFF/PLY, tets .mesh/.node or
// their boundary); given by the caller, which knows the mesh formats.
using SaveMeshFn = std::function<void(const std::string& path, const qpreduce::deform::Vertices& V)>;

// Runs the viewer. Returns the exit code; throws std::runtime_error with a
// clear message when there is no display / GL 3.3 context, and on bad input.
int run_viewer(ViewerInput input, const ViewerOptions& options, const SaveMeshFn& save_mesh);

}  // namespace qpr::viewer
