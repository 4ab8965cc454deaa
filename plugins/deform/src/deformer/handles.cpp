#include "qpreduce/deform/deformer/handles.h"

#include "handle_checks.h"

#include "qpreduce/deform/mesh/mesh_check.h"  // kMaxReach

#include <qpreduce/checks.h>

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

namespace qpreduce::deform {

Normalization normalization_of(const Vertices& V) {
  Normalization frame;
  if (V.rows() == 0 || !V.allFinite()) return frame;
  const Eigen::RowVector3d lo = V.colwise().minCoeff(), hi = V.colwise().maxCoeff();
  const double diagonal = (hi - lo).stableNorm();  // no overflow near the largest doubles
  if (!(diagonal > 0.0) || !std::isfinite(diagonal)) return frame;
  frame.centre = (0.5 * lo + 0.5 * hi).transpose();
  frame.scale = diagonal;
  return frame;
}

DeformableMesh normalised(const DeformableMesh& mesh, const Normalization& frame) {
  DeformableMesh out = mesh;
  out.V = (mesh.V.rowwise() - frame.centre.transpose()) / frame.scale;
  return out;
}

double energy_unit(const Normalization& frame, bool tet) {
  return tet ? frame.scale * frame.scale * frame.scale : frame.scale * frame.scale;
}

RotationElements in_given_units(RotationElements elements, const Normalization& frame) {
  if (!elements.is_surface) {
    for (double& w : elements.weight) w *= frame.scale;
  }
  elements.measure *= elements.is_surface ? frame.scale * frame.scale : frame.scale * frame.scale * frame.scale;
  return elements;
}

HandleTargets normalised(const HandleTargets& targets, const Normalization& frame) {
  HandleTargets out = targets;
  out.points = (targets.points.rowwise() - frame.centre.transpose()) / frame.scale;
  for (auto& T : out.patch_transforms) {
    T.col(3) = (T.leftCols<3>() * frame.centre + T.col(3) - frame.centre) / frame.scale;
  }
  return out;
}

double reach_in_frame(const HandleTargets& targets, const Normalization& frame, const Handles& handles,
                      std::string* where) {
  double reach = 0.0;
  Index farthest = -1;  // a point handle (< 0: none), or points.rows() + the transform's index
  const auto take = [&](double r, Index which) {
    if (!(r <= reach)) {  // NaN or inf wins too
      reach = std::isnan(r) ? std::numeric_limits<double>::infinity() : r;
      farthest = which;
    }
  };
  const Index points = targets.points.rows();
  for (Index i = 0; i < points; ++i)
    take(((targets.points.row(i).transpose() - frame.centre) / frame.scale).cwiseAbs().maxCoeff(), i);
  for (size_t k = 0; k < targets.patch_transforms.size(); ++k) {
    const Eigen::Matrix<double, 3, 4>& T = targets.patch_transforms[k];
    const Eigen::Vector3d t = (T.leftCols<3>() * frame.centre + T.col(3) - frame.centre) / frame.scale;
    take(std::max(T.leftCols<3>().cwiseAbs().maxCoeff(), t.cwiseAbs().maxCoeff()), points + static_cast<Index>(k));
  }
  if (where && farthest >= 0) {
    const size_t k = static_cast<size_t>(farthest - points);
    *where = farthest < points              ? std::string("a point handle's target")
             : k < handles.patches.size() ? fmt::format("patch {}'s transform", handles.patches[k])
                                            : std::string("a patch transform");
  }
  return reach;
}

std::string reach_message(const std::string& where, double reach) {
  return fmt::format(
      "{} reaches {:.3g} bounding-box diagonals from the rest pose's centre: handle targets beyond {:g} diagonals "
      "overflow in the energy (check the transform or target)",
      where, reach, kMaxReach);
}

double handle_residual(const DeformableMesh& m, const Handles& handles, const HandleTargets& targets,
                       const Eigen::Ref<const Vertices>& deformed) {
  check_size("handle_residual: deformed vertex count", m.V.rows(), deformed.rows());
  check_size("handle_residual: deformed columns", 3, deformed.cols());
  detail::check_patch_labels(m, "handle_residual");
  detail::check_handles(handles, m.V.rows(), m.patch_types);
  if (targets.points.rows() != static_cast<Index>(handles.points.size()) ||
      (targets.points.rows() > 0 && targets.points.cols() != 3) ||
      targets.patch_transforms.size() != handles.patches.size()) {
    throw std::invalid_argument(fmt::format(
        "handle_residual: {} point handles and {} prescribed patches, but targets for {} points and {} patches{}",
        handles.points.size(), handles.patches.size(), targets.points.rows(), targets.patch_transforms.size(),
        targets.points.rows() == 0 && targets.patch_transforms.empty() ? " (no frame yet?)" : ""));
  }
  double worst = 0.0;
  for (size_t h = 0; h < handles.points.size(); ++h) {
    const PointHandle& ph = handles.points[h];
    Eigen::RowVector3d p = Eigen::RowVector3d::Zero();
    for (size_t i = 0; i < ph.vertices.size(); ++i)
      p += (ph.weights.empty() ? 1.0 : ph.weights[i]) * deformed.row(ph.vertices[i]);
    worst = std::max(worst, (p - targets.points.row(static_cast<Index>(h))).norm());
  }
  for (Index v = 0; v < m.V.rows(); ++v) {
    if (m.patch_of_vertex.empty() || m.patch_of_vertex[v] < 0) continue;
    const Index p = m.patch_of_vertex[v];
    Eigen::Vector3d target;
    if (m.patch_types[p] == PatchType::Fixed) {
      target = m.V.row(v).transpose();
    } else {
      const auto it = std::find(handles.patches.begin(), handles.patches.end(), p);
      if (it == handles.patches.end()) continue;  // a free patch has no target
      const auto& T = targets.patch_transforms[static_cast<size_t>(it - handles.patches.begin())];
      target = T.leftCols<3>() * m.V.row(v).transpose() + T.col(3);
    }
    worst = std::max(worst, (deformed.row(v).transpose() - target).norm());
  }
  return worst;
}

LinearProxies exact_handle_proxies(const DeformableMesh& model, const Handles& handles, Index more) {
  const Index n = model.V.rows();
  try {
    detail::check_handles(handles, n, model.patch_types);
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument(std::string("exact handles: ") + e.what());
  }
  std::vector<Index> seeds;
  std::vector<char> seen(static_cast<size_t>(n), 0);
  for (size_t h = 0; h < handles.points.size(); ++h) {
    const PointHandle& ph = handles.points[h];
    if (ph.vertices.size() != 1) {
      throw std::invalid_argument(fmt::format(
          "exact handles: point handle {} is a group of {} vertices; only single-vertex handles become proxies "
          "(hold the group as a patch to meet it exactly)",
          h, ph.vertices.size()));
    }
    const Index v = ph.vertices[0];
    const bool in_patch = !model.patch_of_vertex.empty() && model.patch_of_vertex[static_cast<size_t>(v)] >= 0;
    if (in_patch || seen[static_cast<size_t>(v)]++) continue;
    seeds.push_back(v);
  }
  const Index room = n - static_cast<Index>(seeds.size());
  if (model.is_tet()) return linear_proxies_fps(model.V, model.T, std::min(more, room), seeds);
  return linear_proxies_fps(model.V, model.F, std::min(more, room), seeds);
}

}  // namespace qpreduce::deform
