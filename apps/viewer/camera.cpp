#include "camera.h"

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>

namespace qpr::viewer {

namespace {
// World vector from (x right, y up, z towards the default eye) in the frame
// whose up is `up_axis` (a cyclic permutation, so handedness is kept).
Eigen::Vector3f from_local(const Eigen::Vector3f& l, int up_axis) {
  switch (up_axis) {
    case 0: return {l.y(), l.z(), l.x()};
    case 2: return {l.z(), l.x(), l.y()};
    default: return l;
  }
}
}  // namespace

void Camera::fit(const Eigen::Vector3f& lo, const Eigen::Vector3f& hi, float fill) {
  target = 0.5f * (lo + hi);
  radius = std::max(0.5f * (hi - lo).norm(), 1e-6f);
  distance = radius / std::sin(0.5f * fov_y * fill);
}

Eigen::Vector3f Camera::eye() const {
  const Eigen::Vector3f l(std::cos(pitch) * std::sin(yaw), std::sin(pitch), std::cos(pitch) * std::cos(yaw));
  return target + distance * from_local(l, up_axis);
}

Eigen::Vector3f Camera::right() const {
  return from_local(Eigen::Vector3f(std::cos(yaw), 0.0f, -std::sin(yaw)), up_axis);
}

Eigen::Vector3f Camera::up() const {
  const Eigen::Vector3f back = (eye() - target).normalized();
  return back.cross(right()).normalized();
}

Eigen::Matrix4f Camera::view() const {
  const Eigen::Vector3f z = (eye() - target).normalized(), x = right(), y = z.cross(x);
  Eigen::Matrix4f m = Eigen::Matrix4f::Identity();
  m.block<1, 3>(0, 0) = x.transpose();
  m.block<1, 3>(1, 0) = y.transpose();
  m.block<1, 3>(2, 0) = z.transpose();
  m.block<3, 1>(0, 3) = -m.block<3, 3>(0, 0) * eye();
  return m;
}

Eigen::Matrix4f Camera::projection(float aspect) const {
  const float n = near_ratio * distance, f = distance + 2.0f * radius + n;
  const float t = 1.0f / std::tan(0.5f * fov_y);
  Eigen::Matrix4f p = Eigen::Matrix4f::Zero();
  p(0, 0) = t / aspect;
  p(1, 1) = t;
  p(2, 2) = -(f + n) / (f - n);
  p(2, 3) = -2.0f * f * n / (f - n);
  p(3, 2) = -1.0f;
  return p;
}

void Camera::orbit(float dx, float dy) {
  const float rad_per_px = 0.008f;
  yaw -= rad_per_px * dx;
  pitch = std::clamp(pitch + rad_per_px * dy, -1.55f, 1.55f);
}

void Camera::pan(float dx, float dy, float height) {
  const float world_per_px = 2.0f * distance * std::tan(0.5f * fov_y) / std::max(height, 1.0f);
  target += world_per_px * (-dx * right() + dy * up());
}

void Camera::zoom(float steps) { distance *= std::pow(0.9f, steps); }

}  // namespace qpr::viewer
