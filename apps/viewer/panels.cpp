// The interactive viewer's ImGui panels: Model (sizes, options, recompute,
// soft handles), Frame (reconstruction path and timings) and Edit (colours,
// selection, handles, playback, recording, files).
#include "interactive.h"
#include "appearance.h"
#include "motion.h"

#include <fmt/format.h>
#include <imgui.h>

#include <algorithm>

namespace qpr::viewer {

using namespace qpreduce;
using namespace qpreduce::deform;

void Interactive::panels() {
  model_panel();
  frame_panel();
  refine_panel();
  edit_panel();
}

// Sizes of the model, the precompute options and Recompute, soft handles.
void Interactive::model_panel() {
  const PrecomputeSummary& pre = session_.summary();
  ImGui::SetNextWindowPos(ImVec2(10, 10), ImGuiCond_FirstUseEver);
  ImGui::SetNextWindowSize(ImVec2(340, 0), ImGuiCond_FirstUseEver);
  ImGui::Begin("Model");
  ImGui::TextUnformatted(session_.input().name.c_str());
  ImGui::Text("%ld vertices, %ld elements", long(session_.rest().rows()), long(pre.elements));
  ImGui::Text("proxies: %ld linear, %ld rotational, %ld patches", long(pre.linear_proxies), long(pre.rotational_proxies),
              long(pre.patches));
  ImGui::Text("reduced size %ld, precompute %.2f s", long(pre.reduced_size), pre.total_seconds);
  if (session_.deformer().ready() && session_.deformer().model()) {
    const Eigen::VectorXd psi = session_.deformer().cluster_scales();
    ImGui::Text("model %s, cluster scales %.3f … %.3f", session_.deformer().model()->name().c_str(),
                psi.size() ? psi.minCoeff() : 1.0, psi.size() ? psi.maxCoeff() : 1.0);
  }
  ImGui::Separator();
  ImGui::InputInt("linear proxies", &ui_linear_);
  ImGui::InputInt("rotational proxies", &ui_rotational_);
  ImGui::InputFloat("alpha", &ui_alpha_, 0.01f, 0.1f, "%.4g");
  ImGui::InputFloat("beta", &ui_beta_, 0.01f, 0.1f, "%.4g");
  ImGui::InputFloat("gamma", &ui_gamma_, 0.1f, 1.0f, "%.4g");
  ImGui::Checkbox("conformal (scaled rotations)", &ui_conformal_);
  if (ui_conformal_) ImGui::InputFloat("psi bound", &ui_psi_, 0.1f, 0.5f, "%.3g");
  ImGui::InputInt("iterations", &ui_iterations_);
  if (session_.precomputing()) {
    ImGui::ProgressBar(static_cast<float>(session_.progress()), ImVec2(-1, 0), session_.progress_stage().c_str());
  } else if (ImGui::Button("Recompute")) {
    DeformerOptions d = session_.options();
    d.linear_proxies = std::max(1, ui_linear_);
    d.rotational_proxies = std::max(1, ui_rotational_);
    d.energy.alpha = std::max(0.0f, ui_alpha_);
    d.energy.beta = session_.input().scenario.model.is_tet() ? 0.0 : std::max(0.0f, ui_beta_);
    d.energy.gamma = std::max(0.0f, ui_gamma_);
    d.model = ui_conformal_ ? ModelKind::Conformal : ModelKind::Arap;
    d.conformal_bound = std::max(1.01f, ui_psi_);
    d.iterations = std::clamp(ui_iterations_, 1, 1000);
    session_.precompute_async(d);
  }
  if (!session_.precompute_error().empty()) ImGui::TextColored(ImVec4(0.8f, 0.1f, 0.1f, 1), "%s", session_.precompute_error().c_str());
  ImGui::Separator();
  bool changed = ImGui::Checkbox("soft handles", &ui_soft_);
  if (ui_soft_) changed |= ImGui::InputFloat("delta", &ui_delta_, 0.0f, 0.0f, "%.4g", ImGuiInputTextFlags_EnterReturnsTrue);
  if (changed) {
    session_.constraint_options().soft = ui_soft_;
    session_.constraint_options().delta = std::max(1e-12f, ui_delta_);
    constraints_changed();
  }
  ImGui::End();
}

// GPU / CPU reconstruction and the smoothed timings.
void Interactive::frame_panel() {
  ImGui::SetNextWindowPos(ImVec2(10, 330), ImGuiCond_FirstUseEver);
  ImGui::SetNextWindowSize(ImVec2(340, 0), ImGuiCond_FirstUseEver);
  ImGui::Begin("Frame");
  int path = wanted_ == Reconstruction::Gpu ? 0 : 1;
  bool path_changed = ImGui::RadioButton("GPU", &path, 0);  // both buttons drawn every frame
  path_changed |= ImGui::RadioButton("CPU", &path, 1);
  if (path_changed) {
    wanted_ = path == 0 ? Reconstruction::Gpu : Reconstruction::Cpu;
    cancel_refine();  // back to reduced frames on the new path
    if (ready_) session_.set_reconstruction(wanted_, &renderer_);
  }
  ImGui::Text("running: %s", to_string(session_.reconstruction()));
  if (!session_.gpu_unavailable_reason().empty()) ImGui::TextWrapped("GPU unavailable: %s", session_.gpu_unavailable_reason().c_str());
  ImGui::Text("iteration      %8.1f us", shown_.iteration_us);
  ImGui::Text("OP (handles)   %8.3f ms", op_ms_);
  ImGui::Text("solve          %8.3f ms", shown_.solve_ms);
  ImGui::Text("reconstruction %8.3f ms", shown_.reconstruction_ms);
  ImGui::Text("frame          %8.3f ms", shown_.frame_ms);
  ImGui::Text("handle residual %.2e (/ bbox diag.)", shown_.handle_residual);
  ImGui::Text("fixed-point residual %.2e after %d rounds", stats_.fixed_point_residual, stats_.iterations);
  ImGui::Text("rounds ended by the %s", to_string(stats_.stop));
  ImGui::Text("display %.1f fps", ImGui::GetIO().Framerate);
  if (!op_note_.empty()) ImGui::TextWrapped("%s", op_note_.c_str());
  ImGui::End();
}

// The full-space refine: its state, the quality of the pose shown, and the
// classic ARAP energy on request.
void Interactive::refine_panel() {
  ImGui::SetNextWindowPos(ImVec2(10, 580), ImGuiCond_FirstUseEver);
  ImGui::Begin("Refine", nullptr, ImGuiWindowFlags_AlwaysAutoResize);
  if (ImGui::Checkbox("refine when the handles rest", &auto_refine_)) {
    cancel_refine();
    rest_.restart();  // switched on: a refine after the next rest period
  }
  if (ready_) {
    const RefineStatus st = refine_worker().status();
    const RefineSummary& r = st.summary;
    switch (st.state) {
      case RefineStatus::State::Idle: ImGui::TextUnformatted("refine: idle"); break;
      case RefineStatus::State::Running:
        if (st.preparing)
          ImGui::Text("refine: preparing (factoring), %.2f s", st.seconds);
        else
          ImGui::Text("refine: running, %d rounds, %.2f s", st.rounds, st.seconds);
        break;
      case RefineStatus::State::Done:
        ImGui::Text("refine: done, %d rounds, %.2f s%s", r.rounds, r.seconds, r.converged ? "" : " (round limit)");
        ImGui::Text("ARAP energy %.6g (reduced pose %.6g)", r.arap_energy, r.initial_energy);
        ImGui::Text("from the reduced pose: RMS %.2e, max %.2e", r.rms_from_input, r.max_from_input);
        ImGui::TextUnformatted("(/ bbox diagonal; drawn until a handle moves)");
        break;
      case RefineStatus::State::Cancelled: ImGui::TextUnformatted("refine: cancelled (handles moved or changed)"); break;
      case RefineStatus::State::Failed: ImGui::TextWrapped("refine failed: %s", st.message.c_str()); break;
    }
    if (ImGui::Button("ARAP energy")) {
      Vertices V;
      session_.positions(renderer_, &V);
      shown_arap_ = session_.arap_energy(V);
    }
    if (shown_arap_ >= 0.0) {
      ImGui::SameLine();
      ImGui::Text("%.6g (%s pose)", shown_arap_, showing_refined_ ? "refined" : "reduced");
    }
  }
  ImGui::End();
}

// Colours, selection, handles, scenario playback, motion and files.
void Interactive::edit_panel() {
  ImGui::SetNextWindowPos(ImVec2(float(fb_w_) / scale_ - 330, 10), ImGuiCond_FirstUseEver);
  ImGui::SetNextWindowSize(ImVec2(320, 0), ImGuiCond_FirstUseEver);
  ImGui::Begin("Edit");
  const char* modes[] = {"rotational clusters", "linear proxies", "affine patches", "deviation from rest"};
  int mode = static_cast<int>(style_.mode);
  if (ImGui::Combo("colour", &mode, modes, 4)) {
    style_.mode = static_cast<ColorMode>(mode);
    if (ready_) renderer_.set_colors(vertex_colors(style_.mode, session_));
  }
  if (style_.mode == ColorMode::Deviation) ImGui::SliderFloat("ramp top (diag.)", &deviation_, 0.001f, 0.5f, "%.3f");
  ImGui::Text("selection: %zu vertices", selection_.size());
  if (ImGui::Button("Make handle (H)")) make_handle();
  ImGui::SameLine();
  if (ImGui::Button("Clear (Esc)")) selection_.clear(), renderer_.set_markers(1, {});
  handle_list();
  if (session_.scenario_frames() > 0) {
    ImGui::Separator();
    ImGui::Checkbox("play scenario (Space)", &playing_);
    int f = static_cast<int>(scenario_frame_);
    if (ImGui::SliderInt("frame", &f, 0, static_cast<int>(session_.scenario_frames()) - 1)) {
      scenario_frame_ = static_cast<size_t>(f);
      session_.pose_scenario_frame(scenario_frame_);
    }
  }
  ImGui::Separator();
  motion_controls();
  file_controls();
  if (!message_.empty()) ImGui::TextWrapped("%s", message_.c_str());
  ImGui::End();
}

// One row per handle: select, reset, delete.
void Interactive::handle_list() {
  auto& handles = session_.handles();
  for (size_t h = 0; h < handles.size(); ++h) {
    ImGui::PushID(static_cast<int>(h));
    if (ImGui::Selectable(handles[h].name.c_str(), active_ == static_cast<int>(h), 0, ImVec2(200, 0))) active_ = static_cast<int>(h);
    ImGui::SameLine();
    if (ImGui::SmallButton("reset")) handles[h].transform.setIdentity();
    ImGui::SameLine();
    if (ImGui::SmallButton("delete")) delete_handle(static_cast<int>(h));
    ImGui::PopID();
  }
}

// Record the handles' motion and save it; replay a recording.
void Interactive::motion_controls() {
  ImGui::InputText("motion", motion_path_, sizeof motion_path_);
  if (!recording_ && ImGui::Button("Record")) recorded_ = HandleMotion{}, recording_ = true;
  if (recording_ && ImGui::Button("Stop and save")) {
    recording_ = false;
    try {
      write_motion(motion_path_, recorded_);
      message_ = fmt::format("wrote {} ({} frames)", motion_path_, recorded_.frames.size());
    } catch (const std::exception& e) {
      message_ = e.what();
    }
  }
  ImGui::SameLine();
  if (ImGui::Button("Replay")) {
    try {
      replay_ = read_motion(motion_path_);
      handles_from_motion(replay_, &session_);
      constraints_changed();
      replay_frame_ = 0;
      replaying_ = true;
    } catch (const std::exception& e) {
      message_ = e.what();
    }
  }
}

// Save the deformed mesh and a screenshot.
void Interactive::file_controls() {
  ImGui::InputText("mesh", mesh_path_, sizeof mesh_path_);
  if (ImGui::Button("Save deformed mesh")) {
    try {
      Vertices V;
      session_.positions(renderer_, &V);
      save_mesh_(mesh_path_, V);
      message_ = std::string("wrote ") + mesh_path_;
    } catch (const std::exception& e) {
      message_ = e.what();
    }
  }
  ImGui::InputText("png", png_path_, sizeof png_path_);
  if (ImGui::Button("Save screenshot")) pending_screenshot_ = png_path_;
}

}  // namespace qpr::viewer
