// qpr viewer — an orbit camera: the eye circles `target` at `distance`,
// `yaw` about the up axis and `pitch` above the horizon (radians). Matrices
// are column-major 4 × 4 floats, OpenGL conventions (right-handed view space,
// the camera looks down −z; clip z in [−w, w]).
#pragma once

#include <vector>

#include <Eigen/Core>

namespace qpr::viewer {

struct Camera {
  Eigen::Vector3f target = Eigen::Vector3f::Zero();
  float distance = 1.0f;
  float yaw = 0.0f, pitch = 0.0f;
  int up_axis = 1;             // 0 x, 1 y, 2 z: the world axis shown upwards
  float fov_y = 0.6f;          // vertical field of view, radians (≈ 34°)
  float near_ratio = 0.01f;    // near plane = near_ratio · distance, far = distance + 2·radius
  float radius = 1.0f;         // the model's bounding-sphere radius (for the far plane)

  // Frames a bounding box: target its centre, distance so the bounding
  // sphere fills `fill` of the vertical view.
  void fit(const Eigen::Vector3f& lo, const Eigen::Vector3f& hi, float fill = 0.85f);
  Eigen::Vector3f eye() const;
  Eigen::Matrix4f view() const;                       // world → view
  Eigen::Matrix4f projection(float aspect) const;     // view → clip
  // Mouse gestures, in pixels of a window `height` pixels tall.
  void orbit(float dx, float dy);
  void pan(float dx, float dy, float height);
  void zoom(float steps);  // > 0 closer
  // The world-space camera axes (right, up) for dragging in the view plane.
  Eigen::Vector3f right() const;
  Eigen::Vector3f up() const;
};

// Whether (x, y) lies inside the closed polygon (px[i], py[i]) (even–odd
// rule; the lasso selection). Fewer than 3 corners: never inside.
inline bool inside_polygon(float x, float y, const std::vector<float>& px, const std::vector<float>& py) {
  bool inside = false;
  const size_t n = px.size();
  if (n < 3 || py.size() != n) return false;
  for (size_t i = 0, j = n - 1; i < n; j = i++) {
    if ((py[i] > y) != (py[j] > y) && x < (px[j] - px[i]) * (y - py[i]) / (py[j] - py[i]) + px[i]) inside = !inside;
  }
  return inside;
}

}  // namespace qpr::viewer
