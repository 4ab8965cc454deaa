// The interactive viewer's mouse and keyboard: camera moves, picking and
// dragging handles, box / lasso / click selection.
#include "interactive.h"

#include <Eigen/Geometry>
#include <imgui.h>

#include <algorithm>
#include <cmath>

namespace qpr::viewer {

using namespace qpreduce;
using namespace qpreduce::deform;

namespace {

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

}  // namespace

Eigen::Matrix4f Interactive::pv() const {
  return camera_.projection(static_cast<float>(fb_w_) / std::max(fb_h_, 1)) * camera_.view();
}

// The handle with a marker within `radius` pixels of (x, y) (framebuffer pixels), or −1.
int Interactive::pick_handle(float x, float y) {
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

// Adds the visible vertices inside the lasso polygon to the selection.
void Interactive::select_lasso() {
  select_where([this](float px, float py) { return inside_polygon(px, py, lasso_x_, lasso_y_); });
  lasso_x_.clear();
  lasso_y_.clear();
}

// Calls fn(vertex, projection) for every vertex visible on screen
// (projected inside the framebuffer and not hidden in the depth buffer).
template <typename Fn>
void Interactive::for_visible(const Fn& fn) {
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
void Interactive::select_where(const Inside& inside) {
  for_visible([&](int v, const Projected& p) {
    if (inside(p.x, p.y)) selection_.insert(v);
  });
  renderer_.set_markers(1, std::vector<unsigned>(selection_.begin(), selection_.end()));
}

// A box (x0, y0)–(x1, y1) adds the visible vertices inside it; a click
// toggles the nearest visible vertex within 10 pixels.
void Interactive::select(float x0, float y0, float x1, float y1, bool click) {
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

Interactive::Pointer Interactive::read_pointer() {
  GLFWwindow* w = context_.window();
  Pointer p;
  glfwGetCursorPos(w, &p.x, &p.y);
  p.x *= scale_, p.y *= scale_;
  p.dx = static_cast<float>(p.x - last_x_), p.dy = static_cast<float>(p.y - last_y_);
  last_x_ = p.x, last_y_ = p.y;
  p.left = glfwGetMouseButton(w, GLFW_MOUSE_BUTTON_LEFT) == GLFW_PRESS;
  p.right = glfwGetMouseButton(w, GLFW_MOUSE_BUTTON_RIGHT) == GLFW_PRESS ||
            glfwGetMouseButton(w, GLFW_MOUSE_BUTTON_MIDDLE) == GLFW_PRESS;
  p.shift = glfwGetKey(w, GLFW_KEY_LEFT_SHIFT) == GLFW_PRESS || glfwGetKey(w, GLFW_KEY_RIGHT_SHIFT) == GLFW_PRESS;
  p.rotate = glfwGetKey(w, GLFW_KEY_R) == GLFW_PRESS;
  p.ctrl = glfwGetKey(w, GLFW_KEY_LEFT_CONTROL) == GLFW_PRESS || glfwGetKey(w, GLFW_KEY_RIGHT_CONTROL) == GLFW_PRESS;
  return p;
}

// Left: shift+ctrl lasso, shift box, on a handle drag it (R held: rotate),
// elsewhere orbit; right or middle: pan; the wheel zooms.
void Interactive::mouse() {
  const Pointer p = read_pointer();
  if (drag_ == Drag::None && !ImGui::GetIO().WantCaptureMouse) {
    start_drag(p);
    return;
  }
  if (!p.left && !p.right) {
    end_drag(p);
    return;
  }
  continue_drag(p);
}

void Interactive::start_drag(const Pointer& p) {
  const double x = p.x, y = p.y;
  if (p.left) {
    start_x_ = x, start_y_ = y;
    const int h = p.shift ? -1 : pick_handle(static_cast<float>(x), static_cast<float>(y));
    if (p.shift && p.ctrl) drag_ = Drag::Lasso, lasso_x_ = {float(x)}, lasso_y_ = {float(y)};
    else if (p.shift) drag_ = Drag::Box;
    else if (h >= 0) active_ = h, drag_ = p.rotate ? Drag::Rotate : Drag::Translate, playing_ = replaying_ = false;
    else drag_ = Drag::Orbit;
  } else if (p.right) {
    drag_ = Drag::Pan;
  }
  ImGuiIO& io = ImGui::GetIO();
  if (io.MouseWheel != 0.0f) camera_.zoom(io.MouseWheel);
}

void Interactive::end_drag(const Pointer& p) {
  const double x = p.x, y = p.y;
  if (drag_ == Drag::Box) {
    const bool click = std::hypot(x - start_x_, y - start_y_) < 4.0 * scale_;
    select(static_cast<float>(start_x_), static_cast<float>(start_y_), static_cast<float>(x), static_cast<float>(y), click);
  } else if (drag_ == Drag::Lasso) {
    select_lasso();
  }
  drag_ = Drag::None;
}

void Interactive::continue_drag(const Pointer& p) {
  const double x = p.x, y = p.y;
  switch (drag_) {
    case Drag::Lasso:
      if (std::hypot(x - lasso_x_.back(), y - lasso_y_.back()) > 3.0 * scale_)
        lasso_x_.push_back(float(x)), lasso_y_.push_back(float(y));
      break;
    case Drag::Orbit: camera_.orbit(p.dx, p.dy); break;
    case Drag::Pan: camera_.pan(p.dx, p.dy, static_cast<float>(fb_h_)); break;
    case Drag::Translate:
    case Drag::Rotate: drag_handle(p.dx, p.dy, p.rotate); break;
    default: break;
  }
}

// Moves the active handle: a translation in the view plane (so that it
// follows the pointer at its depth), or a rotation about its pivot.
void Interactive::drag_handle(float dx, float dy, bool rotate) {
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
}

void Interactive::draw_box() {
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

void Interactive::keys() {
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

}  // namespace qpr::viewer
