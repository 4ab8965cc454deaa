// The interactive viewer: set-up, the main loop, handles, playback and
// recording (mouse and keys: picking.cpp; panels: panels.cpp).
#include "interactive.h"
#include "modes.h"
#include "appearance.h"
#include "motion.h"
#include "run_files.h"

#include "reports.h"

#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <imgui.h>
#include <backends/imgui_impl_glfw.h>
#include <backends/imgui_impl_opengl3.h>

#include <algorithm>

namespace qpr::viewer {

using namespace qpreduce;
using namespace qpreduce::deform;

Interactive::Interactive(Session& session, const ViewerOptions& o, const SaveMeshFn& save_mesh)
    : session_(session),
      o_(o),
      save_mesh_(save_mesh),
      context_(o.width, o.height, "qpr view — " + session.input().name, true),
      renderer_(session.rest(), session.input().faces),
      rest_(o.refine_after_still_s) {
  set_camera(&camera_, session.rest(), o);
  style_.mode = o.color;
  deviation_ = o.deviation_scale;
  wanted_ = o.reconstruction;
  const DeformerOptions& d = session.input().options;
  ui_linear_ = static_cast<int>(d.linear_proxies);
  ui_rotational_ = static_cast<int>(d.rotational_proxies);
  ui_alpha_ = static_cast<float>(d.energy.alpha);
  ui_beta_ = static_cast<float>(d.energy.beta);
  ui_gamma_ = static_cast<float>(d.energy.gamma);
  ui_conformal_ = d.model == ModelKind::Conformal;
  ui_psi_ = static_cast<float>(d.conformal_bound);
  ui_iterations_ = d.iterations;
  ui_soft_ = session.constraint_options().soft;
  ui_delta_ = static_cast<float>(session.constraint_options().delta);
  // Scenes open posed: the scenario's last frame (the display loop converges
  // to it, warm-started frame after frame).
  session.handles_from_scenario();
  if (session.scenario_frames() > 0) {
    scenario_frame_ = session.scenario_frames() - 1;
    session.pose_scenario_frame(scenario_frame_);
  }
  if (!o.replay.empty()) {
    replay_ = read_motion(o.replay);
    handles_from_motion(replay_, &session);
    replaying_ = true;
  }
  IMGUI_CHECKVERSION();
  ImGui::CreateContext();
  ImGui::GetIO().IniFilename = nullptr;
  ImGui::StyleColorsLight();
  ImGui_ImplGlfw_InitForOpenGL(context_.window(), true);
  ImGui_ImplOpenGL3_Init("#version 330 core");
  glfwSwapInterval(1);
  session_.precompute_async(session.input().options);
}

Interactive::~Interactive() {
  ImGui_ImplOpenGL3_Shutdown();
  ImGui_ImplGlfw_Shutdown();
  ImGui::DestroyContext();
}

int Interactive::run() {
  int frame = 0;
  const bool logging = !o_.window_log.empty();
  while (!glfwWindowShouldClose(context_.window())) {
    if (logging) {
      const double now = glfwGetTime();
      if (!log_.empty()) log_.back().frame_ms = 1e3 * (now - log_.back().start_s);
      log_.push_back({});
      log_.back().start_s = now;
      frame_log_ = &log_.back();
    }
    glfwPollEvents();
    if (session_.poll()) on_precomputed();
    ImGui_ImplOpenGL3_NewFrame();
    ImGui_ImplGlfw_NewFrame();
    ImGui::NewFrame();
    glfwGetFramebufferSize(context_.window(), &fb_w_, &fb_h_);
    int win_w = 1, win_h = 1;
    glfwGetWindowSize(context_.window(), &win_w, &win_h);
    scale_ = static_cast<float>(fb_w_) / std::max(win_w, 1);
    if (fb_w_ > 0 && fb_h_ > 0) {
      mouse();
      keys();
      advance_playback();
      watch_handles();
      if (ready_ && !showing_refined_) {
        try {
          stats_ = session_.step(&renderer_);
          if (frame_log_ != nullptr) {
            frame_log_->stepped = true;
            frame_log_->rounds = stats_.iterations;
            frame_log_->stop = to_string(stats_.stop);
          }
          smooth();
        } catch (const std::exception& e) {
          message_ = e.what();
        }
      }
      target_.resize(fb_w_, fb_h_, o_.samples);
      target_.bind();
      style_.deviation_scale = deviation_ * static_cast<float>(session_.diagonal());
      renderer_.draw(camera_, fb_w_, fb_h_, style_);
      target_.resolve();
      if (!pending_screenshot_.empty()) {
        try {
          write_png(pending_screenshot_, target_.read_rgb());
          message_ = "wrote " + pending_screenshot_;
        } catch (const std::exception& e) {
          message_ = e.what();
        }
        pending_screenshot_.clear();
      }
      target_.blit_to_screen(fb_w_, fb_h_);
      panels();
      draw_box();
    }
    ImGui::Render();
    glViewport(0, 0, fb_w_, fb_h_);
    ImGui_ImplOpenGL3_RenderDrawData(ImGui::GetDrawData());
    // With a replay, the frames count from the end of the precompute (the
    // replay starts then), so that a test sees all of it on any machine.
    const bool counting = o_.replay.empty() || ready_;
    const bool last = o_.max_frames > 0 && counting && ++frame >= o_.max_frames;
    if (last && !o_.window_screenshot.empty())
      write_png(qpr::run_files().stage(o_.window_screenshot), read_window(fb_w_, fb_h_));
    glfwSwapBuffers(context_.window());
    if (frame_log_ != nullptr) frame_log_->refined_shown = showing_refined_;
    if (last) break;
  }
  if (logging) {
    log_.back().frame_ms = 1e3 * (glfwGetTime() - log_.back().start_s);
    frame_log_ = nullptr;
    write_window_log();
  }
  return 0;
}

void Interactive::write_window_log() const {
  nlohmann::json frames = nlohmann::json::array();
  for (const FrameLog& f : log_) {
    nlohmann::json j = {{"start_s", f.start_s},   {"frame_ms", f.frame_ms}, {"moved", f.moved},
                        {"stepped", f.stepped}, {"refined_shown", f.refined_shown}};
    if (!f.event.empty()) j["event"] = f.event;
    if (f.stepped) {
      j["rounds"] = f.rounds;
      j["stop"] = f.stop;
    }
    if (f.cancel_ms >= 0) {
      j["cancel_ms"] = f.cancel_ms;
      j["worker_state"] = f.worker_state;
      j["worker_rounds"] = f.worker_rounds;
    }
    frames.push_back(std::move(j));
  }
  write_json(qpr::run_files().stage(o_.window_log),
             {{"format", "qpr-window-log"},
              {"version", 1},
              {"refine_after_still_s", o_.refine_after_still_s},
              {"frames", std::move(frames)}},
             "window log");
}

void Interactive::on_precomputed() {
  ready_ = true;
  session_.set_reconstruction(wanted_, &renderer_);
  renderer_.set_colors(vertex_colors(style_.mode, session_));
  renderer_.set_markers(0, handle_markers(session_));
  constraints_changed();
}

void Interactive::constraints_changed() {
  if (!ready_) return;
  cancel_refine();
  rest_.restart();  // a new handle set counts as a move
  try {
    op_ms_ = session_.update_constraints(&op_note_);
  } catch (const std::exception& e) {
    message_ = e.what();
  }
  renderer_.set_markers(0, handle_markers(session_));
}

void Interactive::smooth() {  // exponential moving average for a readable panel
  const double a = 0.1;
  shown_.iteration_us += a * (stats_.iteration_us - shown_.iteration_us);
  shown_.solve_ms += a * (stats_.solve_ms - shown_.solve_ms);
  shown_.reconstruction_ms += a * (stats_.reconstruction_ms - shown_.reconstruction_ms);
  shown_.frame_ms += a * (stats_.frame_ms - shown_.frame_ms);
  shown_.handle_residual = stats_.handle_residual;
}

void Interactive::make_handle() {
  if (selection_.empty() || !ready_) return;
  try {
    session_.add_handle(std::vector<int>(selection_.begin(), selection_.end()),
                        fmt::format("h{}", session_.handles().size()));
    active_ = static_cast<int>(session_.handles().size()) - 1;
    selection_.clear();
    renderer_.set_markers(1, {});
    stop_recording_if_changed();
    constraints_changed();
  } catch (const std::exception& e) {
    message_ = e.what();
  }
}

void Interactive::delete_handle(int h) {
  if (h < 0 || h >= static_cast<int>(session_.handles().size())) return;
  session_.remove_handle(static_cast<size_t>(h));
  active_ = -1;
  stop_recording_if_changed();
  constraints_changed();
}

void Interactive::stop_recording_if_changed() {
  if (recording_) {
    recording_ = false;
    message_ = "recording stopped: the handles changed";
  }
}

void Interactive::advance_playback() {
  if (!ready_) return;
  if (playing_ && session_.scenario_frames() > 0) {
    session_.pose_scenario_frame(scenario_frame_);
    scenario_frame_ = (scenario_frame_ + 1) % session_.scenario_frames();
  }
  if (replaying_ && !replay_.frames.empty()) {
    apply_motion_frame(replay_, replay_frame_, &session_);
    if (++replay_frame_ >= replay_.frames.size()) replaying_ = false;
  }
  if (recording_) {
    try {
      record_frame(session_.handles(), session_.rest().rows(), &recorded_);
    } catch (const std::exception& e) {
      recording_ = false;
      message_ = e.what();
    }
  }
}

RefineWorker& Interactive::refine_worker() { return session_.refine_worker(o_.refine.value_or(RefineOptions{})); }

// Starts a refine once the handles have been still long enough, cancels it
// when one moves or is grabbed, and swaps in its pose when it finishes.
void Interactive::watch_handles() {
  if (!ready_) return;
  const auto& handles = session_.handles();
  bool moved = drag_ == Drag::Translate || drag_ == Drag::Rotate || handles.size() != last_transforms_.size();
  for (size_t h = 0; !moved && h < handles.size(); ++h) moved = handles[h].transform != last_transforms_[h];
  if (frame_log_ != nullptr) frame_log_->moved = moved;
  if (moved) {
    last_transforms_.resize(handles.size());
    for (size_t h = 0; h < handles.size(); ++h) last_transforms_[h] = handles[h].transform;
    if (frame_log_ != nullptr && refine_started_) {
      const RefineStatus before = refine_worker().status();
      const double t0 = glfwGetTime();
      cancel_refine();
      frame_log_->cancel_ms = 1e3 * (glfwGetTime() - t0);
      frame_log_->event = "refine-cancel";
      frame_log_->worker_state = to_string(before.state);
      frame_log_->worker_rounds = before.rounds;
    } else {
      cancel_refine();
    }
  }
  const bool posed = session_.last_pose().rows() == session_.rest().rows() &&
                     (!session_.handle_set().points.empty() || !session_.handle_set().patches.empty());
  if (rest_.update(moved, glfwGetTime()) && auto_refine_ && posed) {
    refine_worker().start(session_.handle_set(), session_.targets(), session_.last_pose());
    refine_started_ = true;
    if (frame_log_ != nullptr) frame_log_->event = "refine-start";
  }
  if (refine_started_ && !showing_refined_ && refine_worker().poll(&refined_)) {
    session_.show_pose(refined_, &renderer_);
    showing_refined_ = true;
    shown_arap_ = -1.0;
    if (frame_log_ != nullptr) frame_log_->event = "refine-shown";
  }
}

// Back to reduced frames; returns at once (the worker stops before its next round).
void Interactive::cancel_refine() {
  if (refine_started_) refine_worker().cancel();
  refine_started_ = showing_refined_ = false;
  shown_arap_ = -1.0;
}

int run_interactive(Session& session, const ViewerOptions& options, const SaveMeshFn& save_mesh) {
  Interactive app(session, options, save_mesh);
  return app.run();
}

}  // namespace qpr::viewer
