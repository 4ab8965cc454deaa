// DeformerOptions, the Deformer's construction and accessors, and
// apply_sel_def. The session's phases are in precompute.cpp (precompute),
// onsite.cpp (set_handles), frame.cpp (frame, reset_pose), cache.cpp
// (save, load) and state.cpp (the model set-up they share).
#include "qpreduce/deform/deformer/deformer.h"

#include <qpreduce/anderson.h>

#include "state.h"

#include <qpreduce/checks.h>

#include <Eigen/LU>

#include <fmt/format.h>

#include <cmath>
#include <utility>

namespace qpreduce::deform {

bool DeformerOptions::is_valid(std::string* why) const {
  auto fail = [why](std::string msg) {
    if (why) *why = std::move(msg);
    return false;
  };
  std::string sub;
  if (!energy.is_valid(&sub)) return fail("energy: " + sub);
  if (rotational_proxies < 1) return fail(fmt::format("rotational_proxies must be ≥ 1, got {}", rotational_proxies));
  if (linear_proxies < 0) return fail(fmt::format("linear_proxies must be ≥ 0, got {}", linear_proxies));
  if (iterations < 1) return fail(fmt::format("iterations must be ≥ 1, got {}", iterations));
  if (cold_start_rounds < 0 || cold_start_rounds > 100000)
    return fail(fmt::format("cold_start_rounds must be in [0, 100000] (0: off), got {}", cold_start_rounds));
  if (!(cold_start_tolerance >= 0.0) || !std::isfinite(cold_start_tolerance)) {
    return fail(fmt::format("cold_start_tolerance must be finite and ≥ 0, got {}", cold_start_tolerance));
  }
  if (!(tolerance >= 0.0) || !std::isfinite(tolerance)) {
    return fail(fmt::format("tolerance must be finite and ≥ 0, got {}", tolerance));
  }
  if (!(time_budget >= 0.0) || !std::isfinite(time_budget)) {
    return fail(fmt::format("time_budget must be finite and ≥ 0 seconds (0: none), got {}", time_budget));
  }
  if (anderson_window < 0 || anderson_window > AndersonAcceleration::kMaxWindow) {
    return fail(fmt::format("anderson_window must be in [0, {}] (0: off), got {}", AndersonAcceleration::kMaxWindow,
                            anderson_window));
  }
  if (anderson_window > 0 && rotation_fit != ClusterRotationFit::Exact) {
    return fail("anderson_window needs rotation_fit Exact: the safeguard's energy is E′ at the exact Phase 2 input");
  }
  if (round_threads < 0) return fail(fmt::format("round_threads must be ≥ 0 (0: all), got {}", round_threads));
  if (!clustering.is_valid(&sub)) return fail("clustering: " + sub);
  if (!subspace.is_valid(&sub)) return fail("subspace: " + sub);
  if (!custom_model && model == ModelKind::Conformal && (!(conformal_bound > 1.0) || !std::isfinite(conformal_bound))) {
    return fail(fmt::format("conformal_bound must be finite and > 1, got {}", conformal_bound));
  }
  return true;
}

std::shared_ptr<const DeformationModel> DeformerOptions::resolve_model() const {
  if (custom_model) return custom_model;
  return model == ModelKind::Conformal ? make_conformal_model(energy, conformal_bound) : make_arap_model(energy);
}

Deformer::Deformer() : state_(std::make_unique<State>()) {}
Deformer::~Deformer() = default;
Deformer::Deformer(Deformer&&) noexcept = default;
Deformer& Deformer::operator=(Deformer&&) noexcept = default;

bool Deformer::ready() const { return state_->ready; }
Index Deformer::vertex_count() const { return state_->model.n; }
Index Deformer::rotational_proxies() const { return state_->model.d; }
Index Deformer::linear_proxies() const { return state_->model.m; }
Index Deformer::patch_count() const { return state_->model.s; }
Index Deformer::handle_rows() const { return state_->onsite.rows; }
const std::vector<int>& Deformer::clusters() const { return state_->model.clusters; }
const std::vector<int>& Deformer::patch_of_vertex() const { return state_->model.patch_of_vertex; }
const RotationElements& Deformer::elements() const { return state_->model.given_elements; }
const Eigen::VectorXd& Deformer::rotations() const { return state_->pose.S; }
Eigen::VectorXd Deformer::cluster_scales() const {
  const Index d = state_->model.d;
  const Eigen::VectorXd& S = state_->pose.S;
  Eigen::VectorXd psi(d);
  for (Index a = 0; a < d; ++a) psi(a) = std::cbrt(Eigen::Map<const Eigen::Matrix3d>(S.data() + 9 * a).determinant());
  return psi;
}
const std::shared_ptr<const DeformationModel>& Deformer::model() const { return state_->model.energy_model; }
Eigen::Matrix<double, 3, 4> Deformer::patch_transform(Index p) const {
  const detail::Model& model = state_->model;
  const detail::Pose& pose = state_->pose;
  if (p < 0 || p >= model.s) {
    throw std::invalid_argument(fmt::format("patch_transform: patch {} outside [0, {})", p, model.s));
  }
  const Index base = 3 * model.m + 12 * p;
  Eigen::Matrix<double, 3, 4> T;
  for (int a = 0; a < 3; ++a) {
    for (int c = 0; c < 3; ++c) T(a, c) = pose.x(base + 3 * a + c);
    T(a, 3) = pose.x(base + 9 + a);
  }
  // [A | t] in the normalised frame maps x to σ·(A·(x − c)/σ + t) + c.
  const Normalization& f = model.frame;
  T = pose.r0 * T;
  T.col(3) = f.scale * T.col(3) + f.centre - T.leftCols<3>() * f.centre;
  return T;
}
const Deformer::Normalization& Deformer::normalization() const {
  static const Normalization identity;
  return state_ ? state_->model.frame : identity;
}
const Eigen::Matrix3d& Deformer::global_rotation() const { return state_->pose.r0; }
const Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>& Deformer::reconstruction_basis() const {
  return state_->model.basis;
}
Deformer::RowBlock Deformer::basis_rows() const {
  if (!state_) return {};
  return {state_->model.basis_first, state_->model.basis_count()};
}

void Deformer::basis_block(Index first, Index count, BasisRows* rows) const {
  if (!state_) throw std::invalid_argument("Deformer::basis_block: call precompute or load first");
  if (rows == nullptr) throw std::invalid_argument("Deformer::basis_block: output pointer is null");
  const detail::Model& model = state_->model;
  const RowBlock mine = basis_rows();
  if (count < 0 || first < mine.first || first + count > mine.first + mine.count) {
    throw std::invalid_argument(fmt::format("Deformer::basis_block: rows [{}, {}) outside this deformer's rows [{}, {})",
                                            first, first + count, mine.first, mine.first + mine.count));
  }
  if (model.part_held) {
    model.basis_rows_from(model.part_first_row, model.part_N, model.part_UD, first, count, rows);
  } else if (model.double_basis) {
    *rows = model.basis_double.middleRows(first - mine.first, count).cast<float>();
  } else {
    *rows = model.basis.middleRows(first - mine.first, count);
  }
}
const Eigen::VectorXf& Deformer::reduced_coordinates() const { return state_->pose.wf; }
bool Deformer::double_basis() const { return state_ && state_->model.double_basis; }
const Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>& Deformer::reconstruction_basis_double()
    const {
  return state_->model.basis_double;
}
const Eigen::VectorXd& Deformer::reduced_coordinates_double() const { return state_->pose.wd; }

SelDefScenario apply_sel_def(const std::vector<int>& sel, const Eigen::Matrix4d& def, DeformableMesh* model) {
  const Index n = model->V.rows();
  check_size("apply_sel_def: .sel entries", n, static_cast<Index>(sel.size()));
  check_finite("apply_sel_def: .def matrix", def);
  model->patch_types = {PatchType::Fixed, PatchType::Affine};
  model->patch_of_vertex.assign(static_cast<size_t>(n), -1);
  Index fixed = 0, handle = 0;
  for (Index v = 0; v < n; ++v) {
    switch (sel[v]) {
      case 0: model->patch_of_vertex[v] = 0; ++fixed; break;
      case 1: break;
      case 2: model->patch_of_vertex[v] = 1; ++handle; break;
      default:
        throw std::invalid_argument(fmt::format("apply_sel_def: vertex {} has role {} (expected 0, 1 or 2)", v, sel[v]));
    }
  }
  if (handle == 0) throw std::invalid_argument("apply_sel_def: the selection has no handle vertex (role 2)");
  if (fixed == 0) {
    // No fixed region: keep only the handle patch.
    model->patch_types = {PatchType::Affine};
    for (int& p : model->patch_of_vertex)
      if (p == 1) p = 0;
  }
  SelDefScenario sc;
  sc.handles.patches = {static_cast<Index>(model->patch_types.size()) - 1};
  sc.targets.points.resize(0, 3);
  sc.targets.patch_transforms = {def.topRows<3>()};
  return sc;
}

void PrecomputeSummary::add_details(Report* out) const {
  out->add("vertices", vertices)
      .add("elements", elements)
      .add("rotational_proxies", rotational_proxies)
      .add("linear_proxies", linear_proxies)
      .add("patches", patches)
      .add("reduced_size", reduced_size)
      .add("assembled_elements", assembled_elements)
      .add("subspace", subspace.report())
      .add("clustering_seconds", clustering_seconds)
      .add("assembly_seconds", assembly_seconds)
      .add("subspace_seconds", subspace_seconds)
      .add("reduction_seconds", reduction_seconds)
      .add("total_seconds", total_seconds);
}

void FrameSummary::add_details(Report* out) const {
  out->add("iterations", iterations)
      .add("last_change", last_change)
      .add("fixed_point_residual", fixed_point_residual)
      .add("model_energy", model_energy)
      .add("rejected_steps", rejected_steps)
      .add("second_order", second_order)
      .add("cold_start", cold_start)
      .add("rotation_kept", rotation_kept)
      .add("stop", stop)
      .add("solve_seconds", solve_seconds)
      .add("reconstruct_seconds", reconstruct_seconds)
      .add("total_seconds", total_seconds);
}

}  // namespace qpreduce::deform
