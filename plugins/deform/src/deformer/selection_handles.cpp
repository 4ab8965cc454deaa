#include "qpreduce/deform/deformer/selection_handles.h"

#include <Eigen/Eigenvalues>
#include <fmt/format.h>

#include <algorithm>
#include <stdexcept>

namespace qpreduce::deform {

namespace {

void check_selection(const Vertices& V, const std::vector<int>& selection) {
  if (selection.empty()) throw std::invalid_argument("selection_handles: no vertex selected");
  for (int v : selection)
    if (v < 0 || v >= V.rows())
      throw std::invalid_argument(fmt::format("selection_handles: vertex {} outside [0, {})", v, V.rows()));
}

Eigen::Vector3d mean_position(const Vertices& V, const std::vector<int>& selection) {
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
  for (int v : selection) c += V.row(v).transpose();
  c /= static_cast<double>(selection.size());
  return c;
}

// The selection split by the sign of its offsets along its two main axes;
// empty quadrants dropped.
std::vector<std::vector<int>> quadrants(const Vertices& V, const std::vector<int>& selection, const Eigen::Vector3d& c) {
  Eigen::Matrix3d scatter = Eigen::Matrix3d::Zero();
  for (int v : selection) {
    const Eigen::Vector3d d = V.row(v).transpose() - c;
    scatter += d * d.transpose();
  }
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(scatter);  // eigenvalues ascending
  const Eigen::Vector3d a1 = eig.eigenvectors().col(2), a2 = eig.eigenvectors().col(1);
  std::vector<std::vector<int>> groups(kMaxSelectionPoints);
  for (int v : selection) {
    const Eigen::Vector3d d = V.row(v).transpose() - c;
    groups[(d.dot(a1) >= 0 ? 1 : 0) + (d.dot(a2) >= 0 ? 2 : 0)].push_back(v);
  }
  groups.erase(std::remove_if(groups.begin(), groups.end(), [](const auto& g) { return g.empty(); }), groups.end());
  return groups;
}

}  // namespace

SelectionHandles selection_handles(const Vertices& V, const std::vector<int>& selection) {
  check_selection(V, selection);
  SelectionHandles out;
  out.centroid = mean_position(V, selection);
  std::vector<std::vector<int>> groups;
  if (selection.size() <= kMaxSelectionPoints) {
    for (int v : selection) groups.push_back({v});
  } else {
    groups = quadrants(V, selection, out.centroid);
  }
  for (const auto& g : groups) {
    PointHandle p;
    p.vertices.assign(g.begin(), g.end());
    if (g.size() > 1) p.weights.assign(g.size(), 1.0 / static_cast<double>(g.size()));
    out.points.push_back(std::move(p));
  }
  return out;
}

}  // namespace qpreduce::deform
