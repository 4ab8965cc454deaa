#include "viewer.h"

#include "context.h"
#include "motion.h"

#include <qpreduce/deform/mesh/geometry.h>
#include <qpreduce/support.h>

#include <Eigen/Geometry>
#include <fmt/format.h>
#include <imgui.h>
#include <backends/imgui_impl_glfw.h>
#include <backends/imgui_impl_opengl3.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <set>
#include <stdexcept>

#include <unistd.h>

namespace qpr::viewer {

using namespace qpreduce;
using namespace qpreduce::deform;

namespace {

constexpr float kPi = 3.14159265f;

Eigen::Vector3f palette(int i) {
  // Hues spread by the golden ratio; pastel so that shading stays readable.
  const float h = std::fmod(0.11f + 0.6180339887f * static_cast<float>(i), 1.0f) * 6.0f;
  const float s = 0.5f, v = 0.92f, c = v * s, x = c * (1.0f - std::fabs(std::fmod(h, 2.0f) - 1.0f)), m = v - c;
  const int k = static_cast<int>(h);
  const Eigen::Vector3f rgb = k == 0 ? Eigen::Vector3f(c, x, 0) : k == 1 ? Eigen::Vector3f(x, c, 0)
                            : k == 2 ? Eigen::Vector3f(0, c, x) : k == 3 ? Eigen::Vector3f(0, x, c)
                            : k == 4 ? Eigen::Vector3f(x, 0, c) : Eigen::Vector3f(c, 0, x);
  return rgb + Eigen::Vector3f::Constant(m);
}

// Per-vertex colours of a categorical mode (the deviation mode is coloured in the shader).
std::vector<Eigen::Vector3f> vertex_colors(ColorMode mode, const Session& session) {
  const Vertices& V = session.rest();
  const Index n = V.rows();
  std::vector<Eigen::Vector3f> colors(static_cast<size_t>(n), Eigen::Vector3f::Constant(0.8f));
  const DeformableMesh& model = session.input().scenario.model;
  if (mode == ColorMode::Clusters && session.deformer().ready()) {
    const std::vector<int>& cl = session.deformer().clusters();
    if (model.is_tet()) {
      for (Index t = 0; t < model.T.rows(); ++t)
        for (int c = 0; c < 4; ++c) colors[model.T(t, c)] = palette(cl[t]);
    } else {
      for (Index v = 0; v < n && v < static_cast<Index>(cl.size()); ++v) colors[v] = palette(cl[v]);
    }
  } else if (mode == ColorMode::LinearProxies) {
    const auto& groups = session.linear_proxies().groups;
    if (groups.empty()) return colors;
    // Groups colour their members; single-vertex samples colour their
    // nearest vertices (Euclidean), which shows where each proxy acts.
    std::vector<int> owner(static_cast<size_t>(n), -1);
    std::vector<Eigen::Vector3d> samples;
    std::vector<int> sample_group;
    for (size_t g = 0; g < groups.size(); ++g) {
      if (groups[g].size() == 1) {
        samples.push_back(V.row(groups[g][0]).transpose());
        sample_group.push_back(static_cast<int>(g));
      }
      for (Index v : groups[g]) owner[v] = static_cast<int>(g);
    }
    for (Index v = 0; v < n; ++v) {
      int best = -1;
      double best_d = INFINITY;
      for (size_t s = 0; s < samples.size(); ++s) {
        const double d = (V.row(v).transpose() - samples[s]).squaredNorm();
        if (d < best_d) best_d = d, best = sample_group[s];
      }
      const int g = (owner[v] >= 0 && groups[owner[v]].size() > 1) ? owner[v] : best;
      if (g >= 0) colors[v] = palette(g);
    }
    for (int g : sample_group) colors[groups[g][0]] = Eigen::Vector3f(0.1f, 0.1f, 0.1f);
  } else if (mode == ColorMode::Patches) {
    for (Index v = 0; v < n && v < static_cast<Index>(model.patch_of_vertex.size()); ++v)
      if (model.patch_of_vertex[v] >= 0) colors[v] = palette(model.patch_of_vertex[v] + 3);
  }
  return colors;
}

std::vector<unsigned> handle_markers(const Session& session) {
  std::vector<unsigned> all;
  for (const ViewHandle& h : const_cast<Session&>(session).handles()) all.insert(all.end(), h.vertices.begin(), h.vertices.end());
  return all;
}

// Frames the rest pose and, when given, the deformed one.
void set_camera(Camera* camera, const Vertices& V, const ViewerOptions& o, const Vertices* deformed = nullptr) {
  Eigen::Vector3f lo = V.colwise().minCoeff().cast<float>().transpose();
  Eigen::Vector3f hi = V.colwise().maxCoeff().cast<float>().transpose();
  if (deformed && deformed->rows() > 0) {
    lo = lo.cwiseMin(deformed->colwise().minCoeff().cast<float>().transpose());
    hi = hi.cwiseMax(deformed->colwise().maxCoeff().cast<float>().transpose());
  }
  camera->up_axis = o.up_axis;
  camera->fit(lo, hi);
  camera->yaw = o.yaw_deg * kPi / 180.0f;
  camera->pitch = o.pitch_deg * kPi / 180.0f;
  camera->zoom(o.zoom);
}

void stderr_progress(const std::string& stage, double fraction) {
  std::fprintf(stderr, "\r  precompute %3d%% %-20s", static_cast<int>(100 * fraction), stage.c_str());
  if (fraction >= 1.0) std::fprintf(stderr, "\n");
  std::fflush(stderr);
}

double median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

// Replays motion frame f: the recorded handles must be the session's handles.
void apply_motion_frame(const HandleMotion& motion, size_t f, Session* session) {
  auto& handles = session->handles();
  const auto& frame = motion.frames[std::min(f, motion.frames.size() - 1)];
  for (size_t h = 0; h < handles.size() && h < frame.size(); ++h) handles[h].transform = frame[h];
}

// Replaces the session's handles by the recorded ones.
void handles_from_motion(const HandleMotion& motion, Session* session) {
  if (motion.vertex_count != session->rest().rows())
    throw std::runtime_error(fmt::format("the recording is for {} vertices, the mesh has {}", motion.vertex_count,
                                         session->rest().rows()));
  if (motion.frames.empty()) throw std::runtime_error("the recording has no frame");
  session->handles_from_scenario();
  std::vector<ViewHandle> patches;
  for (const ViewHandle& h : session->handles())
    if (h.patch >= 0) patches.push_back(h);
  session->handles().clear();
  for (const auto& h : motion.handles) {
    if (h.patch >= 0) {
      auto it = std::find_if(patches.begin(), patches.end(), [&](const ViewHandle& p) { return p.patch == h.patch; });
      if (it == patches.end()) throw std::runtime_error(fmt::format("the recording moves patch {}, which this scene does not prescribe", h.patch));
      session->handles().push_back(*it);
    } else {
      session->add_handle(h.vertices, h.name);
    }
  }
  apply_motion_frame(motion, 0, session);
}

// ---- headless ----

int run_headless(Session& session, const ViewerOptions& o, const SaveMeshFn& save_mesh) {
  GlContext context(o.width, o.height, "qpr view", false);
  MeshRenderer renderer(session.rest(), session.input().faces);
  RenderTarget target;
  target.resize(o.width, o.height, o.samples);

  session.precompute(session.input().options, isatty(fileno(stderr)) ? ProgressFn(stderr_progress) : ProgressFn());
  HandleMotion motion;
  if (!o.replay.empty()) {
    motion = read_motion(o.replay);
    handles_from_motion(motion, &session);
  } else {
    session.handles_from_scenario();
  }
  session.set_reconstruction(o.reconstruction, &renderer);
  std::string note;
  const double op_ms = session.update_constraints(&note);
  if (!note.empty()) std::fprintf(stderr, "  note: %s\n", note.c_str());

  const size_t frames = o.replay.empty() ? session.scenario_frames() : motion.frames.size();
  std::vector<double> iter_us, recon_ms, frame_ms;
  double residual = 0.0;
  for (size_t f = 0; f < frames; ++f) {
    if (o.replay.empty()) session.pose_scenario_frame(f); else apply_motion_frame(motion, f, &session);
    const FrameStats s = session.step(&renderer);
    iter_us.push_back(s.iteration_us);
    recon_ms.push_back(s.reconstruction_ms);
    frame_ms.push_back(s.frame_ms);
    residual = std::max(residual, s.handle_residual);
  }
  // GPU path: compare the read-back positions with a CPU reconstruction of the same w.
  double gpu_cpu = -1.0;
  if (session.reconstruction() == Reconstruction::Gpu) {
    Vertices gpu;
    renderer.read_positions(&gpu);
    gpu_cpu = (gpu - session.cpu_reconstruction()).cwiseAbs().maxCoeff() / session.diagonal();
  }

  renderer.set_colors(vertex_colors(o.color, session));
  if (o.show_handles) renderer.set_markers(0, handle_markers(session));
  Camera camera;
  Vertices last;
  session.positions(renderer, &last);
  set_camera(&camera, session.rest(), o, &last);
  MeshRenderer::Style style;
  style.mode = o.color;
  style.deviation_scale = o.deviation_scale * static_cast<float>(session.diagonal());
  style.marker_size = std::max(3.0f, o.height / 180.0f);
  target.bind();
  renderer.draw(camera, o.width, o.height, style);
  target.resolve();
  write_png(o.screenshot, target.read_rgb());
  if (!o.out_mesh.empty()) {
    Vertices V;
    session.positions(renderer, &V);
    save_mesh(o.out_mesh, V);
  }

  const PrecomputeSummary& pre = session.summary();
  fmt::print("{}: {} vertices, {} linear / {} rotational proxies, {} patches; {} frames\n", session.input().name,
             pre.vertices, pre.linear_proxies, pre.rotational_proxies, pre.patches, frames);
  fmt::print("  renderer        {}\n", context.description());
  fmt::print("  reconstruction  {}{}\n", to_string(session.reconstruction()),
             session.gpu_unavailable_reason().empty() ? "" : " (GPU unavailable: " + session.gpu_unavailable_reason() + ")");
  fmt::print("  precompute {:.2f} s, OP {:.3f} ms, iteration {:.1f} µs, reconstruction {:.3f} ms, frame {:.3f} ms (medians)\n",
             pre.total_seconds, op_ms, median(iter_us), median(recon_ms), median(frame_ms));
  fmt::print("  handle residual {:.2e} (max, / bbox diagonal)", residual);
  if (gpu_cpu >= 0) fmt::print(", GPU vs CPU max |Δ| {:.2e} (/ bbox diagonal)", gpu_cpu);
  fmt::print("\n  wrote {}\n", o.screenshot);
  if (!o.stats_json.empty()) {
    nlohmann::json j{{"name", session.input().name},
                     {"renderer", context.description()},
                     {"reconstruction", session.reconstruction() == Reconstruction::Gpu ? "gpu" : "cpu"},
                     {"gpu_unavailable_reason", session.gpu_unavailable_reason()},
                     {"vertices", pre.vertices},
                     {"reduced_size", pre.reduced_size},
                     {"frames", frames},
                     {"precompute_s", pre.total_seconds},
                     {"op_ms", op_ms},
                     {"iteration_us", median(iter_us)},
                     {"reconstruction_ms", median(recon_ms)},
                     {"frame_ms", median(frame_ms)},
                     {"handle_residual_max", residual},
                     {"gpu_cpu_max_deviation", gpu_cpu},
                     {"screenshot", o.screenshot}};
    std::ofstream out(o.stats_json);
    if (!out) throw std::runtime_error(o.stats_json + ": cannot write the stats");
    out << j.dump(2) << "\n";
  }
  return 0;
}

// ---- interactive ----

struct Projected {
  float x, y, depth;  // pixels from the top-left, window depth in [0, 1]
  bool in_front;
};

Projected project(const Eigen::Matrix4f& pv, const Eigen::Vector3d& p, int width, int height) {
  const Eigen::Vector4f c = pv * Eigen::Vector4f(float(p.x()), float(p.y()), float(p.z()), 1.0f);
  if (c.w() <= 0.0f) return {0, 0, 1, false};
  const Eigen::Vector3f ndc = c.head<3>() / c.w();
  return {(0.5f * ndc.x() + 0.5f) * width, (0.5f - 0.5f * ndc.y()) * height, 0.5f * ndc.z() + 0.5f, true};
}

class Interactive {
 public:
  Interactive(Session& session, const ViewerOptions& o, const SaveMeshFn& save_mesh)
      : session_(session), o_(o), save_mesh_(save_mesh), context_(o.width, o.height, "qpr view — " + session.input().name, true),
        renderer_(session.rest(), session.input().faces) {
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
  ~Interactive() {
    ImGui_ImplOpenGL3_Shutdown();
    ImGui_ImplGlfw_Shutdown();
    ImGui::DestroyContext();
  }

  int run() {
    int frame = 0;
    while (!glfwWindowShouldClose(context_.window())) {
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
        if (ready_) {
          try {
            stats_ = session_.step(&renderer_);
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
      const bool last = o_.max_frames > 0 && ++frame >= o_.max_frames;
      if (last && !o_.window_screenshot.empty()) write_png(o_.window_screenshot, read_window(fb_w_, fb_h_));
      glfwSwapBuffers(context_.window());
      if (last) break;
    }
    return 0;
  }

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

  void on_precomputed() {
    ready_ = true;
    session_.set_reconstruction(wanted_, &renderer_);
    renderer_.set_colors(vertex_colors(style_.mode, session_));
    renderer_.set_markers(0, handle_markers(session_));
    constraints_changed();
  }

  void constraints_changed() {
    if (!ready_) return;
    try {
      op_ms_ = session_.update_constraints(&op_note_);
    } catch (const std::exception& e) {
      message_ = e.what();
    }
    renderer_.set_markers(0, handle_markers(session_));
  }

  void smooth() {  // exponential moving average for a readable panel
    const double a = 0.1;
    shown_.iteration_us += a * (stats_.iteration_us - shown_.iteration_us);
    shown_.solve_ms += a * (stats_.solve_ms - shown_.solve_ms);
    shown_.reconstruction_ms += a * (stats_.reconstruction_ms - shown_.reconstruction_ms);
    shown_.frame_ms += a * (stats_.frame_ms - shown_.frame_ms);
    shown_.handle_residual = stats_.handle_residual;
  }

  Eigen::Matrix4f pv() const {
    return camera_.projection(static_cast<float>(fb_w_) / std::max(fb_h_, 1)) * camera_.view();
  }

  // The handle with a marker within `radius` pixels of (x, y) (framebuffer pixels), or −1.
  int pick_handle(float x, float y) {
    Vertices V;
    session_.positions(renderer_, &V);
    if (V.rows() == 0) return -1;
    const Eigen::Matrix4f m = pv();
    const float radius = 10.0f * scale_;
    int best = -1;
    float best_d = radius * radius;
    const auto& handles = session_.handles();
    for (size_t h = 0; h < handles.size(); ++h)
      for (unsigned v : handles[h].vertices) {
        const Projected p = project(m, V.row(v).transpose(), fb_w_, fb_h_);
        const float d = (p.x - x) * (p.x - x) + (p.y - y) * (p.y - y);
        if (p.in_front && d < best_d) best_d = d, best = static_cast<int>(h);
      }
    return best;
  }

  // Visible vertices inside the pixel rectangle (or the nearest one to a click).
  // Adds the visible vertices inside the lasso polygon to the selection.
  void select_lasso() {
    select_where([this](float px, float py) { return inside_polygon(px, py, lasso_x_, lasso_y_); });
    lasso_x_.clear();
    lasso_y_.clear();
  }

  // Calls fn(vertex, projection) for every vertex visible on screen
  // (projected inside the framebuffer and not hidden in the depth buffer).
  template <typename Fn>
  void for_visible(const Fn& fn) {
    Vertices V;
    session_.positions(renderer_, &V);
    if (V.rows() == 0) V = session_.rest();
    const std::vector<float> depth = target_.read_depth_buffer();
    const Eigen::Matrix4f m = pv();
    for (Index v = 0; v < V.rows(); ++v) {
      const Projected p = project(m, V.row(v).transpose(), fb_w_, fb_h_);
      const int px = static_cast<int>(p.x), py = static_cast<int>(p.y);
      if (!p.in_front || px < 0 || py < 0 || px >= fb_w_ || py >= fb_h_) continue;
      if (p.depth > depth[static_cast<size_t>(py) * fb_w_ + px] + 2e-3f) continue;  // hidden
      fn(static_cast<int>(v), p);
    }
  }

  template <typename Inside>
  void select_where(const Inside& inside) {
    for_visible([&](int v, const Projected& p) {
      if (inside(p.x, p.y)) selection_.insert(v);
    });
    renderer_.set_markers(1, std::vector<unsigned>(selection_.begin(), selection_.end()));
  }

  // A box (x0, y0)–(x1, y1) adds the visible vertices inside it; a click
  // toggles the nearest visible vertex within 10 pixels.
  void select(float x0, float y0, float x1, float y1, bool click) {
    if (!click) {
      const float lo_x = std::min(x0, x1), hi_x = std::max(x0, x1), lo_y = std::min(y0, y1), hi_y = std::max(y0, y1);
      select_where([&](float x, float y) { return x >= lo_x && x <= hi_x && y >= lo_y && y <= hi_y; });
      return;
    }
    int nearest = -1;
    float nearest_d = (10.0f * scale_) * (10.0f * scale_);
    for_visible([&](int v, const Projected& p) {
      const float d = (p.x - x0) * (p.x - x0) + (p.y - y0) * (p.y - y0);
      if (d < nearest_d) nearest_d = d, nearest = v;
    });
    if (nearest >= 0 && !selection_.erase(nearest)) selection_.insert(nearest);
    renderer_.set_markers(1, std::vector<unsigned>(selection_.begin(), selection_.end()));
  }

  void make_handle() {
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

  void delete_handle(int h) {
    if (h < 0 || h >= static_cast<int>(session_.handles().size())) return;
    session_.remove_handle(static_cast<size_t>(h));
    active_ = -1;
    stop_recording_if_changed();
    constraints_changed();
  }

  void stop_recording_if_changed() {
    if (recording_) {
      recording_ = false;
      message_ = "recording stopped: the handles changed";
    }
  }

  void mouse() {
    ImGuiIO& io = ImGui::GetIO();
    GLFWwindow* w = context_.window();
    double x = 0, y = 0;
    glfwGetCursorPos(w, &x, &y);
    x *= scale_, y *= scale_;
    const float dx = static_cast<float>(x - last_x_), dy = static_cast<float>(y - last_y_);
    last_x_ = x, last_y_ = y;
    const bool left = glfwGetMouseButton(w, GLFW_MOUSE_BUTTON_LEFT) == GLFW_PRESS;
    const bool right = glfwGetMouseButton(w, GLFW_MOUSE_BUTTON_RIGHT) == GLFW_PRESS ||
                       glfwGetMouseButton(w, GLFW_MOUSE_BUTTON_MIDDLE) == GLFW_PRESS;
    const bool shift = glfwGetKey(w, GLFW_KEY_LEFT_SHIFT) == GLFW_PRESS || glfwGetKey(w, GLFW_KEY_RIGHT_SHIFT) == GLFW_PRESS;
    const bool rotate = glfwGetKey(w, GLFW_KEY_R) == GLFW_PRESS;
    const bool ctrl = glfwGetKey(w, GLFW_KEY_LEFT_CONTROL) == GLFW_PRESS || glfwGetKey(w, GLFW_KEY_RIGHT_CONTROL) == GLFW_PRESS;
    if (drag_ == Drag::None && !io.WantCaptureMouse) {
      if (left) {
        start_x_ = x, start_y_ = y;
        const int h = shift ? -1 : pick_handle(static_cast<float>(x), static_cast<float>(y));
        if (shift && ctrl) drag_ = Drag::Lasso, lasso_x_ = {float(x)}, lasso_y_ = {float(y)};
        else if (shift) drag_ = Drag::Box;
        else if (h >= 0) active_ = h, drag_ = rotate ? Drag::Rotate : Drag::Translate, playing_ = replaying_ = false;
        else drag_ = Drag::Orbit;
      } else if (right) {
        drag_ = Drag::Pan;
      }
      if (io.MouseWheel != 0.0f) camera_.zoom(io.MouseWheel);
      return;
    }
    if (!left && !right) {
      if (drag_ == Drag::Box) {
        const bool click = std::hypot(x - start_x_, y - start_y_) < 4.0 * scale_;
        select(static_cast<float>(start_x_), static_cast<float>(start_y_), static_cast<float>(x), static_cast<float>(y), click);
      } else if (drag_ == Drag::Lasso) {
        select_lasso();
      }
      drag_ = Drag::None;
      return;
    }
    switch (drag_) {
      case Drag::Lasso:
        if (std::hypot(x - lasso_x_.back(), y - lasso_y_.back()) > 3.0 * scale_)
          lasso_x_.push_back(float(x)), lasso_y_.push_back(float(y));
        break;
      case Drag::Orbit: camera_.orbit(dx, dy); break;
      case Drag::Pan: camera_.pan(dx, dy, static_cast<float>(fb_h_)); break;
      case Drag::Translate:
      case Drag::Rotate: {
        ViewHandle& h = session_.handles()[active_];
        const Eigen::Vector4d c4 = h.transform * h.pivot.homogeneous();
        const Eigen::Vector3d c = c4.head<3>();
        if (drag_ == Drag::Translate && !rotate) {
          const double depth = (camera_.eye().cast<double>() - c).norm();
          const double per_px = 2.0 * depth * std::tan(0.5 * camera_.fov_y) / std::max(fb_h_, 1);
          const Eigen::Vector3d d = per_px * (dx * camera_.right().cast<double>() - dy * camera_.up().cast<double>());
          Eigen::Matrix4d T = Eigen::Matrix4d::Identity();
          T.block<3, 1>(0, 3) = d;
          h.transform = T * h.transform;
        } else {
          const Eigen::Vector3d axis_view = (camera_.eye().cast<double>() - c).normalized();
          const Eigen::Matrix3d R = (Eigen::AngleAxisd(0.01 * dx, axis_view) *
                                     Eigen::AngleAxisd(0.01 * dy, camera_.right().cast<double>())).toRotationMatrix();
          Eigen::Matrix4d T = Eigen::Matrix4d::Identity();
          T.topLeftCorner<3, 3>() = R;
          T.block<3, 1>(0, 3) = c - R * c;
          h.transform = T * h.transform;
        }
        break;
      }
      default: break;
    }
  }

  void draw_box() {
    if (drag_ == Drag::Lasso && lasso_x_.size() >= 2) {
      const float s = 1.0f / scale_;
      std::vector<ImVec2> pts;
      for (size_t i = 0; i < lasso_x_.size(); ++i) pts.emplace_back(lasso_x_[i] * s, lasso_y_[i] * s);
      ImGui::GetForegroundDrawList()->AddPolyline(pts.data(), static_cast<int>(pts.size()), IM_COL32(20, 150, 230, 255),
                                                  ImDrawFlags_Closed, 1.5f);
      return;
    }
    if (drag_ != Drag::Box) return;
    double x = 0, y = 0;
    glfwGetCursorPos(context_.window(), &x, &y);
    const float s = 1.0f / scale_;
    ImGui::GetForegroundDrawList()->AddRect(ImVec2(float(start_x_) * s, float(start_y_) * s), ImVec2(float(x), float(y)),
                                            IM_COL32(20, 150, 230, 255), 0.0f, 0, 1.5f);
  }

  void keys() {
    if (ImGui::GetIO().WantCaptureKeyboard) return;
    if (ImGui::IsKeyPressed(ImGui::GetKeyIndex(ImGuiKey_Delete)) || ImGui::IsKeyPressed(ImGui::GetKeyIndex(ImGuiKey_Backspace)))
      delete_handle(active_);
    if (ImGui::IsKeyPressed(ImGui::GetKeyIndex(ImGuiKey_Escape))) {
      selection_.clear();
      renderer_.set_markers(1, {});
    }
    if (ImGui::IsKeyPressed(ImGui::GetKeyIndex(ImGuiKey_Space))) playing_ = !playing_;
    if (ImGui::IsKeyPressed(GLFW_KEY_H)) make_handle();
  }

  void advance_playback() {
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

  void panels() {
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

    ImGui::SetNextWindowPos(ImVec2(10, 330), ImGuiCond_FirstUseEver);
    ImGui::SetNextWindowSize(ImVec2(340, 0), ImGuiCond_FirstUseEver);
    ImGui::Begin("Frame");
    int path = wanted_ == Reconstruction::Gpu ? 0 : 1;
    if (ImGui::RadioButton("GPU", &path, 0) | ImGui::RadioButton("CPU", &path, 1)) {
      wanted_ = path == 0 ? Reconstruction::Gpu : Reconstruction::Cpu;
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
    ImGui::Text("display %.1f fps", ImGui::GetIO().Framerate);
    if (!op_note_.empty()) ImGui::TextWrapped("%s", op_note_.c_str());
    ImGui::End();

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
    if (!message_.empty()) ImGui::TextWrapped("%s", message_.c_str());
    ImGui::End();
  }

  std::string pending_screenshot_;
};

}  // namespace

int run_viewer(ViewerInput input, const ViewerOptions& options, const SaveMeshFn& save_mesh) {
  if (options.width < 16 || options.height < 16 || options.width > 8192 || options.height > 8192)
    throw std::invalid_argument(fmt::format("image size {}×{} outside [16, 8192]", options.width, options.height));
  if (input.faces.rows() == 0) throw std::invalid_argument("the mesh has no triangle to draw");
  Session session(std::move(input));
  if (!options.screenshot.empty()) return run_headless(session, options, save_mesh);
  Interactive app(session, options, save_mesh);
  return app.run();
}

}  // namespace qpr::viewer
