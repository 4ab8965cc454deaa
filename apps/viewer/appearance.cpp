#include "appearance.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>

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

}  // namespace

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
void set_camera(Camera* camera, const Vertices& V, const ViewerOptions& o, const Vertices* deformed) {
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

}  // namespace qpr::viewer
