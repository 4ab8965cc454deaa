// ARAP in libigl's terms: arap() and ArapSolver (arap.h).
#include "qpreduce/deform/arap/arap.h"

#include "qpreduce/deform/proxies/linear_proxies.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

namespace qpreduce::deform {

namespace {

DeformableMesh make_model(const Vertices& V, const ElementsRef& F, const char* who) {
  if (F.cols() != 3 && F.cols() != 4) {
    throw std::invalid_argument(
        fmt::format("{}: F must have 3 columns (triangles) or 4 (tetrahedra), got {}", who, F.cols()));
  }
  if (F.rows() == 0) throw std::invalid_argument(fmt::format("{}: F has no elements", who));
  DeformableMesh model;
  model.V = V;
  if (F.cols() == 3) {
    model.F = F;
  } else {
    model.T = F;
  }
  return model;
}

Handles point_handles(const std::vector<Index>& b, Index n, const char* who) {
  if (b.empty()) throw std::invalid_argument(fmt::format("{}: b is empty: hold at least one vertex", who));
  std::vector<Index> sorted = b;
  std::sort(sorted.begin(), sorted.end());
  for (size_t i = 0; i < b.size(); ++i) {
    if (b[i] < 0 || b[i] >= n) {
      throw std::invalid_argument(fmt::format("{}: b[{}] = {} is outside [0, {})", who, i, b[i], n));
    }
  }
  const auto twice = std::adjacent_find(sorted.begin(), sorted.end());
  if (twice != sorted.end()) {
    throw std::invalid_argument(fmt::format("{}: b lists vertex {} twice (one target per held vertex)", who, *twice));
  }
  Handles handles;
  handles.points.reserve(b.size());
  for (Index v : b) handles.points.push_back(PointHandle{{v}, {}});
  return handles;
}

void check_targets(const Vertices& bc, size_t h, const char* who) {
  if (bc.rows() != static_cast<Index>(h)) {
    throw std::invalid_argument(
        fmt::format("{}: bc has {} rows: expected {} (one per vertex of b)", who, bc.rows(), h));
  }
  if (!bc.allFinite()) throw std::invalid_argument(fmt::format("{}: bc contains NaN or infinite entries", who));
}

}  // namespace

RefineSummary arap(const Vertices& V, const ElementsRef& F, const std::vector<Index>& b, const Vertices& bc,
                   Vertices* U, const RefineOptions& options) {
  if (U == nullptr) throw std::invalid_argument("arap: U is null");
  const DeformableMesh model = make_model(V, F, "arap");
  const Handles handles = point_handles(b, V.rows(), "arap");
  check_targets(bc, b.size(), "arap");
  if (U->rows() != 0 && U->rows() != V.rows()) {
    throw std::invalid_argument(fmt::format(
        "arap: U has {} rows: expected {} (an initial guess) or 0 (start from the rest pose V)", U->rows(), V.rows()));
  }
  Refiner refiner;
  refiner.precompute(model, options);
  HandleTargets targets;
  targets.points = bc;
  Vertices out;
  RefineSummary summary = refiner.refine(handles, targets, *U, &out);
  *U = std::move(out);
  return summary;
}

bool ArapSolverOptions::is_valid(std::string* why) const {
  auto fail = [&](std::string m) {
    if (why) *why = std::move(m);
    return false;
  };
  std::string inner;
  if (!deformer.is_valid(&inner)) return fail("deformer: " + inner);
  if (!refine.is_valid(&inner)) return fail("refine: " + inner);
  if (max_rounds < 1) return fail(fmt::format("max_rounds must be ≥ 1, got {}", max_rounds));
  if (!(tolerance >= 0.0) || !std::isfinite(tolerance)) {
    return fail(fmt::format("tolerance must be finite and ≥ 0, got {}", tolerance));
  }
  if (!(max_basis_gb >= 0.0) || !std::isfinite(max_basis_gb)) {
    return fail(fmt::format("max_basis_gb must be finite and ≥ 0 (0: no limit), got {}", max_basis_gb));
  }
  return true;
}

struct ArapSolver::State {
  DeformableMesh model;
  std::vector<Index> b;
  Handles handles;
  HandleTargets targets;
  ArapSolverOptions options;
  Deformer deformer;
  ConstraintSummary handle_summary;
  std::unique_ptr<Refiner> refiner;  // made at the first refine()
  double reconstruction_error = std::numeric_limits<double>::quiet_NaN();
  bool ready = false;
};

ArapSolver::ArapSolver() : state_(std::make_unique<State>()) {}
ArapSolver::~ArapSolver() = default;
ArapSolver::ArapSolver(ArapSolver&&) noexcept = default;
ArapSolver& ArapSolver::operator=(ArapSolver&&) noexcept = default;

PrecomputeSummary ArapSolver::precompute(const Vertices& V, const ElementsRef& F, const std::vector<Index>& b,
                                         const ArapSolverOptions& options) {
  std::string why;
  if (!options.is_valid(&why)) throw std::invalid_argument("ArapSolverOptions: " + why);
  auto st = std::make_unique<State>();
  st->model = make_model(V, F, "ArapSolver::precompute");
  st->handles = point_handles(b, V.rows(), "ArapSolver::precompute");
  st->b = b;
  st->options = options;
  // Every held vertex its own linear proxy, then samples around them (as
  // many as the options ask, within what the mesh has).
  st->model.linear = exact_handle_proxies(st->model, st->handles, options.deformer.linear_proxies);
  const double n = static_cast<double>(V.rows()), d = 3.0 * static_cast<double>(st->model.linear.count());
  const double gb = 8.0 * 3.0 * n * d / 1e9;
  if (options.max_basis_gb > 0.0 && gb > options.max_basis_gb) {
    PrecomputeSummary refused;
    refused.status = Status::NotRun;
    refused.message = fmt::format(
        "refused before any allocation: {} held vertices on a {}-vertex mesh make a subspace whose null-space block N alone is {:.1f} GB "
        "(3n × {} doubles), above ArapSolverOptions::max_basis_gb = {:g}; for one solve call arap() (full space, no "
        "subspace), hold regions as patches (Deformer), or raise max_basis_gb",
        b.size(), V.rows(), gb, static_cast<Index>(d), options.max_basis_gb);
    return refused;
  }
  // Its one handle set, on linear proxies that are vertices, is eliminated
  // (docs/engine.md): Phase 1's fast path would be prepared for nothing.
  DeformerOptions deformer_options = options.deformer;
  deformer_options.prepare_onsite = false;
  PrecomputeSummary summary = st->deformer.precompute(st->model, deformer_options);
  if (!summary.ok()) return summary;
  st->deformer.set_rounds(options.max_rounds, options.tolerance);
  st->handle_summary = st->deformer.set_handles(st->handles);
  if (!st->handle_summary.usable()) {
    summary.status = st->handle_summary.status;
    summary.message = "the handle set failed: " + st->handle_summary.message;
    return summary;
  }
  st->ready = true;
  state_ = std::move(st);
  return summary;
}

FrameSummary ArapSolver::solve(const Vertices& bc, Vertices* U) {
  if (!ready()) throw std::invalid_argument("ArapSolver::solve: call precompute first (and check its summary)");
  if (U == nullptr) throw std::invalid_argument("ArapSolver::solve: U is null");
  if (U->rows() != vertex_count()) U->resize(vertex_count(), 3);
  return solve(bc, Eigen::Map<Vertices>(U->data(), U->rows(), 3));
}

FrameSummary ArapSolver::solve(const Vertices& bc, Eigen::Map<Vertices> U) {
  if (!ready()) throw std::invalid_argument("ArapSolver::solve: call precompute first (and check its summary)");
  State& st = *state_;
  check_targets(bc, st.b.size(), "ArapSolver::solve");
  st.targets.points = bc;
  FrameSummary summary = st.deformer.frame(st.targets, U);
  if (summary.ok() && st.handle_summary.ok()) {
    double worst = 0.0;
    for (size_t i = 0; i < st.b.size(); ++i) {
      worst = std::max(worst, (U.row(st.b[i]) - bc.row(static_cast<Index>(i))).norm());
      U.row(st.b[i]) = bc.row(static_cast<Index>(i));
    }
    st.reconstruction_error = worst;
  }
  return summary;
}

RefineSummary ArapSolver::refine(const Vertices& bc, Vertices* U) {
  const FrameSummary reduced = solve(bc, U);
  if (!reduced.ok()) {
    RefineSummary failed;
    failed.status = reduced.status;
    failed.message = "the reduced solve failed: " + reduced.message;
    return failed;
  }
  State& st = *state_;
  if (!st.refiner) {
    st.refiner = std::make_unique<Refiner>();
    st.refiner->precompute(st.model, st.options.refine);
  }
  Vertices out;
  RefineSummary summary = st.refiner->refine(st.handles, st.targets, *U, &out);
  *U = std::move(out);
  return summary;
}

bool ArapSolver::ready() const { return state_ && state_->ready; }
Index ArapSolver::vertex_count() const { return state_->model.V.rows(); }
const std::vector<Index>& ArapSolver::handle_vertices() const { return state_->b; }
const ConstraintSummary& ArapSolver::handle_summary() const { return state_->handle_summary; }
const Deformer& ArapSolver::deformer() const { return state_->deformer; }
double ArapSolver::reconstruction_handle_error() const { return state_->reconstruction_error; }
const DeformableMesh& ArapSolver::model() const { return state_->model; }

}  // namespace qpreduce::deform
