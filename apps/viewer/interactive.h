// qpr viewer — the interactive window: a main loop that precomputes in the
// background, steps the deformer every frame and draws the mesh and the
// panels. Its members are defined by topic: interactive.cpp (set-up, main
// loop, handles, playback), picking.cpp (mouse, keys, selection),
// panels.cpp (the ImGui panels).
#pragma once

#include "camera.h"
#include "context.h"
#include "motion.h"
#include "renderer.h"
#include "session.h"
#include "viewer.h"

#include <set>
#include <string>
#include <vector>

namespace qpr::viewer {

class Interactive {
 public:
  // Opens the window and the ImGui context, poses the scene (its last
  // scenario frame, or the recording of options.replay) and starts the
  // precompute in the background.
  Interactive(Session& session, const ViewerOptions& o, const SaveMeshFn& save_mesh);
  ~Interactive();
  Interactive(const Interactive&) = delete;
  Interactive& operator=(const Interactive&) = delete;

  // The main loop, until the window closes (or o.max_frames). Returns 0.
  int run();

 private:
  Session& session_;
  const ViewerOptions& o_;
  const SaveMeshFn& save_mesh_;
  GlContext context_;
  MeshRenderer renderer_;
  RenderTarget target_;
  Camera camera_;
  MeshRenderer::Style style_;
  float deviation_ = 0.1f;
  Reconstruction wanted_ = Reconstruction::Gpu;
  bool ready_ = false;
  int fb_w_ = 1, fb_h_ = 1;
  float scale_ = 1.0f;  // framebuffer pixels per window pixel
  FrameStats stats_, shown_;
  double op_ms_ = 0.0;
  std::string message_, op_note_;
  std::string pending_screenshot_;
  // UI state.
  int ui_linear_ = 33, ui_rotational_ = 27, ui_iterations_ = 8;
  float ui_alpha_ = 0.1f, ui_beta_ = 0.1f, ui_gamma_ = 0.0f, ui_psi_ = 2.0f, ui_delta_ = 1e3f;
  bool ui_conformal_ = false;
  bool ui_soft_ = false;
  char mesh_path_[256] = "deformed.obj", png_path_[256] = "screenshot.png", motion_path_[256] = "motion.json";
  // Interaction.
  enum class Drag { None, Orbit, Pan, Box, Lasso, Translate, Rotate } drag_ = Drag::None;
  std::vector<float> lasso_x_, lasso_y_;  // the lasso's corners, framebuffer pixels
  double last_x_ = 0, last_y_ = 0, start_x_ = 0, start_y_ = 0;
  int active_ = -1;  // handle being edited
  std::set<int> selection_;
  // Playback and recording.
  bool playing_ = false, recording_ = false, replaying_ = false;
  size_t scenario_frame_ = 0, replay_frame_ = 0;
  HandleMotion recorded_, replay_;
  // Full-space refine (refine_worker.h): started when the handles have been
  // still for o.refine_after_still_s, cancelled as soon as one moves; its
  // pose is drawn (no reduced frames) until then.
  bool auto_refine_ = true, refine_started_ = false, showing_refined_ = false;
  // The frame log (ViewerOptions::window_log): one entry per displayed frame.
  struct FrameLog {
    double start_s = 0.0, frame_ms = 0.0;  // glfwGetTime at the top of the loop; to the next frame's top
    bool moved = false, stepped = false, refined_shown = false;
    std::string event;        // "", "refine-start", "refine-shown", "refine-cancel"
    double cancel_ms = -1.0;  // refine-cancel: time inside cancel_refine()
    std::string worker_state;  // refine-cancel: the worker's state just before
    int worker_rounds = -1;    // refine-cancel: its rounds so far (Running)
    int rounds = 0;            // stepped: the reduced rounds, and what ended them
    std::string stop;
  };
  std::vector<FrameLog> log_;
  FrameLog* frame_log_ = nullptr;  // this frame's entry (null when not logging)
  void write_window_log() const;
  RestTimer rest_;
  std::vector<Eigen::Matrix4d> last_transforms_;
  qpreduce::deform::Vertices refined_;
  double shown_arap_ = -1.0;  // "ARAP energy" of the pose shown; < 0: not asked since it changed

  // ---- interactive.cpp ----
  void on_precomputed();
  void constraints_changed();
  void smooth();
  void make_handle();
  void delete_handle(int h);
  void stop_recording_if_changed();
  void advance_playback();
  RefineWorker& refine_worker();
  void watch_handles();
  void cancel_refine();

  // ---- picking.cpp ----
  Eigen::Matrix4f pv() const;
  int pick_handle(float x, float y);
  void select_lasso();
  template <typename Fn>
  void for_visible(const Fn& fn);
  template <typename Inside>
  void select_where(const Inside& inside);
  void select(float x0, float y0, float x1, float y1, bool click);
  // The pointer this frame: position (framebuffer pixels), motion since the
  // last frame, buttons and modifier keys.
  struct Pointer {
    double x = 0, y = 0;
    float dx = 0, dy = 0;
    bool left = false, right = false, shift = false, ctrl = false, rotate = false;
  };
  Pointer read_pointer();
  void mouse();
  void start_drag(const Pointer& p);
  void end_drag(const Pointer& p);
  void continue_drag(const Pointer& p);
  void drag_handle(float dx, float dy, bool rotate);
  void draw_box();
  void keys();

  // ---- panels.cpp ----
  void panels();
  void model_panel();
  void frame_panel();
  void refine_panel();
  void edit_panel();
  void handle_list();
  void motion_controls();
  void file_controls();
};

}  // namespace qpr::viewer
