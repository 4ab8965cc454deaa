// Shared parts of the full-space references (reference.h): options, model and
// handle checks, per-vertex targets.
#include "reference_internal.h"

#include "deformer/handle_checks.h"

#include <qpreduce/anderson.h>
#include <qpreduce/checks.h>

#include "qpreduce/deform/deformer/handles.h"
#include "qpreduce/deform/mesh/mesh.h"

#include <Eigen/Dense>
#include <fmt/format.h>

#include <algorithm>
#include <cmath>

namespace qpreduce::deform {

const char* to_string(ReferenceEnergy energy) {
  return energy == ReferenceEnergy::ClassicArap ? "classic ARAP" : "modified ARAP E'";
}

bool ReferenceOptions::is_valid(std::string* why) const {
  auto fail = [why](std::string msg) {
    if (why) *why = std::move(msg);
    return false;
  };
  std::string sub;
  if (energy == ReferenceEnergy::ModifiedArap && !parameters.is_valid(&sub)) return fail("parameters: " + sub);
  if (energy == ReferenceEnergy::ModifiedArap && parameters.gamma != 0.0) {
    return fail("parameters: gamma > 0 (the moving-frame term, Eq. 11) is not modelled by the full-space E' "
                "references; compare with gamma = 0 or against classic ARAP");
  }
  if (max_iterations < 1) return fail(fmt::format("max_iterations must be ≥ 1, got {}", max_iterations));
  for (const auto& [name, v] : {std::pair<const char*, double>{"step_tolerance", step_tolerance},
                                {"energy_tolerance", energy_tolerance},
                                {"function_tolerance", function_tolerance},
                                {"gradient_tolerance", gradient_tolerance},
                                {"parameter_tolerance", parameter_tolerance},
                                {"tolerance", tolerance},
                                {"distance_tolerance", distance_tolerance}}) {
    if (!(v >= 0.0) || !std::isfinite(v)) return fail(fmt::format("{} must be finite and ≥ 0, got {}", name, v));
  }
  if (!frame.allFinite() || (frame.transpose() * frame - Eigen::Matrix3d::Identity()).norm() > 1e-9 ||
      frame.determinant() < 0) {
    return fail("frame must be a rotation (orthonormal, det +1)");
  }
  if (anderson_window < 0 || anderson_window > AndersonAcceleration::kMaxWindow) {
    return fail(fmt::format("anderson_window must be in [0, {}] (0 = plain local-global), got {}",
                            AndersonAcceleration::kMaxWindow, anderson_window));
  }
  if (newton_after < 0) return fail(fmt::format("newton_after must be ≥ 0 (0: rounds only), got {}", newton_after));
  if (threads < 1) return fail(fmt::format("threads must be ≥ 1, got {}", threads));
  return true;
}

namespace detail {

PreparedModel prepare_model(const DeformableMesh& model, const ReferenceOptions& options) {
  std::string why;
  if (!options.is_valid(&why)) throw std::invalid_argument("ReferenceOptions: " + why);
  PreparedModel m;
  detail::check_mesh_elements(model, "reference");
  m.tet = model.is_tet();
  m.V = model.V;
  const Index n = m.V.rows();
  m.elements = m.tet ? tet_elements(model.V, model.T) : spokes_and_rims_elements(model.V, model.F);
  m.parameters = options.parameters;
  if (m.tet) m.parameters.beta = 0.0;
  if (options.energy == ReferenceEnergy::ModifiedArap) {
    if (model.clusters.empty()) {
      throw std::invalid_argument("reference: the modified energy E' needs DeformableMesh::clusters (one per element)");
    }
    ::qpreduce::check_size("reference: clusters", m.elements.size(), static_cast<Index>(model.clusters.size()));
    m.clusters = model.clusters;
    const int lo = *std::min_element(m.clusters.begin(), m.clusters.end());
    if (lo < 0) throw std::invalid_argument(fmt::format("reference: negative cluster label {}", lo));
    m.d = 1 + *std::max_element(m.clusters.begin(), m.clusters.end());
  }
  m.patch_types = model.patch_types;
  detail::check_patch_labels(model, "reference");
  m.patch_of_vertex = model.patch_of_vertex.empty() ? std::vector<int>(static_cast<size_t>(n), -1)
                                                    : model.patch_of_vertex;
  m.components = connected_components(n, m.tet ? ElementsRef(model.T) : ElementsRef(model.F));
  m.diagonal = bounding_box_diagonal(m.V);
  return m;
}

void check_handles(const PreparedModel& m, const Handles& handles) {
  detail::check_handles(handles, m.V.rows(), m.patch_types);
}

void check_targets(const Handles& handles, const HandleTargets& targets) {
  ::qpreduce::check_size("reference: target points", static_cast<Index>(handles.points.size()),
                                 targets.points.rows());
  ::qpreduce::check_size("reference: patch transforms", static_cast<Index>(handles.patches.size()),
                                 static_cast<Index>(targets.patch_transforms.size()));
  if (targets.points.size() > 0) ::qpreduce::check_finite("reference: target points", targets.points);
  for (const auto& T : targets.patch_transforms) ::qpreduce::check_finite("reference: patch transform", T);
}

void check_anchored(const PreparedModel& m, const Handles& handles) {
  std::vector<char> anchored(static_cast<size_t>(m.components.count), 0);
  const Index n = m.V.rows();
  for (Index v = 0; v < n; ++v) {
    const int p = m.patch_of_vertex[v];
    if (p < 0) continue;
    if (m.patch_types[p] == PatchType::Fixed ||
        std::find(handles.patches.begin(), handles.patches.end(), p) != handles.patches.end()) {
      anchored[m.components.vertex_component[v]] = 1;
    }
  }
  for (const PointHandle& ph : handles.points)
    for (Index v : ph.vertices) anchored[m.components.vertex_component[v]] = 1;
  for (Index c = 0; c < m.components.count; ++c) {
    if (anchored[c]) continue;
    Index example = 0;
    while (m.components.vertex_component[example] != c) ++example;
    throw std::invalid_argument(fmt::format(
        "reference: connected component {} of {} (vertex {} among others) has no handle and no Fixed or prescribed "
        "patch, so its position is undetermined; anchor every component",
        c, m.components.count, example));
  }
}

std::vector<PatchTarget> patch_targets(const PreparedModel& m, const Handles& handles, const HandleTargets& targets,
                                       const Eigen::Matrix3d& frame) {
  std::vector<PatchTarget> out;
  for (Index p = 0; p < static_cast<Index>(m.patch_types.size()); ++p) {
    if (m.patch_types[p] != PatchType::Fixed) continue;
    PatchTarget t{p, Eigen::Matrix<double, 3, 4>::Zero()};
    t.transform.leftCols<3>() = frame.transpose();
    out.push_back(t);
  }
  for (size_t i = 0; i < handles.patches.size(); ++i) {
    const Index p = handles.patches[i];
    out.push_back({p, frame.transpose() * targets.patch_transforms[i]});
  }
  return out;
}

DeformableMesh targets_model(const PreparedModel& m) {
  DeformableMesh out;
  out.V = m.V;
  out.patch_of_vertex = m.patch_of_vertex;
  out.patch_types = m.patch_types;
  return out;
}

void rotations_to_world(const Eigen::Matrix3d& frame, Eigen::VectorXd* S) {
  for (Index i = 0; i < S->size() / 9; ++i) {
    Eigen::Map<Eigen::Matrix3d> Si(S->data() + 9 * i);
    Si = frame * Si;
  }
}

double energy_of(const PreparedModel& m, ReferenceEnergy kind, const Vertices& Vp, const Eigen::VectorXd& Q,
                 const Eigen::VectorXd& S) {
  return kind == ReferenceEnergy::ClassicArap
             ? arap_energy(m.V, m.elements, Vp)
             : modified_arap_energy(m.V, m.elements, m.clusters, m.parameters, Vp, Q, S);
}

ReferenceSummary solve_in_frame(const DeformableMesh& model, const HandleTargets& targets, const Vertices& initial,
                                ReferenceSolution* out, const FrameSolve& solve) {
  if (out == nullptr) throw std::invalid_argument("reference: out is null");
  const Normalization f = normalization_of(model.V);
  const Vertices local_initial =
      initial.size() > 0 ? Vertices((initial.rowwise() - f.centre.transpose()) / f.scale) : Vertices();
  ReferenceSummary s = solve(normalised(model, f), normalised(targets, f), local_initial, out);
  to_given_units(f, energy_unit(f, model.is_tet()), &s, out);
  return s;
}

void to_given_units(const Normalization& frame, double energy_unit, ReferenceSummary* summary, ReferenceSolution* out) {
  if (out->V.size() > 0) out->V = (out->V * frame.scale).rowwise() + frame.centre.transpose();
  summary->initial_energy *= energy_unit;
  summary->energy *= energy_unit;
  for (double& e : summary->round_energy) e *= energy_unit;
  summary->handle_residual *= frame.scale;
  summary->last_step *= frame.scale;
}

}  // namespace detail

VertexTargets vertex_targets(const DeformableMesh& model, const Handles& handles, const HandleTargets& targets,
                             double tolerance) {
  const Index n = model.V.rows();
  if (!model.patch_of_vertex.empty()) {
    ::qpreduce::check_size("vertex_targets: patch_of_vertex", n,
                                   static_cast<Index>(model.patch_of_vertex.size()));
  }
  detail::check_targets(handles, targets);
  VertexTargets out;
  out.pinned.assign(static_cast<size_t>(n), 0);
  out.position = Vertices::Zero(n, 3);
  std::vector<std::string> by(static_cast<size_t>(n));
  auto hold = [&](Index v, const Eigen::Vector3d& p, const std::string& what) {
    if (out.pinned[v]) {
      const double gap = (out.position.row(v).transpose() - p).norm();
      if (gap > tolerance) {
        throw std::invalid_argument(fmt::format(
            "conflicting targets: vertex {} is held at ({:.6g}, {:.6g}, {:.6g}) by {} and at ({:.6g}, {:.6g}, "
            "{:.6g}) by {} ({:.3g} apart)",
            v, out.position(v, 0), out.position(v, 1), out.position(v, 2), by[v], p(0), p(1), p(2), what, gap));
      }
      return;
    }
    out.pinned[v] = 1;
    out.position.row(v) = p.transpose();
    by[v] = what;
  };
  if (!model.patch_of_vertex.empty()) {
    for (Index v = 0; v < n; ++v) {
      const int p = model.patch_of_vertex[v];
      if (p < 0) continue;
      if (p >= static_cast<int>(model.patch_types.size())) {
        throw std::invalid_argument(fmt::format("vertex_targets: vertex {} has patch {} outside [-1, {})", v, p,
                                                model.patch_types.size()));
      }
      const Eigen::Vector3d rest = model.V.row(v).transpose();
      if (model.patch_types[p] == PatchType::Fixed) {
        hold(v, rest, fmt::format("Fixed patch {}", p));
        continue;
      }
      const auto it = std::find(handles.patches.begin(), handles.patches.end(), p);
      if (it == handles.patches.end()) continue;
      const auto& T = targets.patch_transforms[static_cast<size_t>(it - handles.patches.begin())];
      hold(v, T.leftCols<3>() * rest + T.col(3), fmt::format("prescribed patch {}", p));
    }
  }
  for (size_t h = 0; h < handles.points.size(); ++h) {
    const PointHandle& ph = handles.points[h];
    if (ph.vertices.size() != 1 || !(ph.weights.empty() || ph.weights[0] == 1.0)) continue;
    const Index v = ph.vertices[0];
    if (v < 0 || v >= n) throw std::invalid_argument(fmt::format("point handle {}: vertex {} outside [0, {})", h, v, n));
    hold(v, targets.points.row(static_cast<Index>(h)).transpose(), fmt::format("point handle {}", h));
  }
  return out;
}

void ReferenceSummary::add_details(Report* out) const {
  out->add("energy_kind", energy_kind)
      .add("converged", converged)
      .add("iterations", iterations)
      .add("initial_energy", initial_energy)
      .add("energy", energy)
      .add("handle_residual", handle_residual)
      .add("last_step", last_step)
      .add("fixed_point_residual", fixed_point_residual)
      .add("estimated_distance", estimated_distance)
      .add("rejected_steps", rejected_steps)
      .add("newton_steps", newton_steps)
      .add("cg_iterations", cg_iterations)
      .add("newton_fallbacks", newton_fallbacks)
      .add("cancelled", cancelled)
      .add("setup_seconds", setup_seconds)
      .add("solve_seconds", solve_seconds)
      .add("solver_report", solver_report);
}

void HandleSetSummary::add_details(Report* out) const {
  out->add("free_coordinates", free_coordinates)
      .add("pinned_coordinates", pinned_coordinates)
      .add("point_rows", point_rows)
      .add("axis_separable", axis_separable)
      .add("seconds", seconds);
}

}  // namespace qpreduce::deform
