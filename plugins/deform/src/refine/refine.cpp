// Refiner: the full-space finish of a reduced pose (refine.h).
#include "qpreduce/deform/refine/refine.h"

#include "qpreduce/deform/mesh/geometry.h"

#include <qpreduce/checks.h>

#include <fmt/format.h>
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <utility>

namespace qpreduce::deform {

namespace {

ReferenceOptions reference_options(const RefineOptions& o) {
  ReferenceOptions ro;
  ro.energy = o.energy;
  ro.parameters = o.parameters;
  ro.backend = o.backend;
  ro.tolerance = o.tolerance;
  ro.distance_tolerance = o.distance_tolerance;
  ro.anderson_window = o.anderson_window;
  ro.newton_after = o.newton_after;
  ro.max_iterations = o.max_iterations;
  ro.threads = o.threads > 0 ? o.threads : std::max(1, omp_get_max_threads());
  return ro;
}

void check_options(const RefineOptions& options) {
  std::string why;
  if (!options.is_valid(&why)) throw std::invalid_argument("RefineOptions: " + why);
}

bool same_handles(const Handles& a, const Handles& b) {
  if (a.patches != b.patches || a.points.size() != b.points.size()) return false;
  for (size_t h = 0; h < a.points.size(); ++h)
    if (a.points[h].vertices != b.points[h].vertices || a.points[h].weights != b.points[h].weights) return false;
  return true;
}

}  // namespace

// The same checks as the local-global options the refine runs with (one
// place for the messages).
bool RefineOptions::is_valid(std::string* why) const {
  if (threads < 0) {
    if (why) *why = fmt::format("threads must be ≥ 0 (0: all), got {}", threads);
    return false;
  }
  return reference_options(*this).is_valid(why);
}

struct Refiner::State {
  RefineOptions options;
  LocalGlobalArap lg;  // computes in the units-free frame (handles.h) itself
  Vertices rest;
  double diagonal = 0.0;
  Handles handles;
  bool has_handles = false;
  bool axis_separable = false;  // of the current handle set's factor
};

Refiner::Refiner() : state_(std::make_unique<State>()) {}
Refiner::~Refiner() = default;
Refiner::Refiner(Refiner&&) noexcept = default;
Refiner& Refiner::operator=(Refiner&&) noexcept = default;

void Refiner::precompute(const DeformableMesh& model, const RefineOptions& options) {
  check_options(options);
  auto st = std::make_unique<State>();
  st->options = options;
  st->lg.precompute(model, reference_options(options));
  st->rest = model.V;
  st->diagonal = bounding_box_diagonal(model.V);
  state_ = std::move(st);
}

void Refiner::set_options(const RefineOptions& options) {
  State& st = *state_;
  if (st.rest.rows() == 0) throw std::invalid_argument("Refiner::set_options: call precompute first");
  check_options(options);
  st.options.tolerance = options.tolerance;
  st.options.distance_tolerance = options.distance_tolerance;
  st.options.anderson_window = options.anderson_window;
  st.options.newton_after = options.newton_after;
  st.options.max_iterations = options.max_iterations;
  st.options.threads = options.threads;
  st.lg.set_iteration_options(reference_options(st.options));
}

const RefineOptions& Refiner::options() const { return state_->options; }

const RotationElements& Refiner::elements() const { return state_->lg.elements(); }

RefineSummary Refiner::refine(const Handles& handles, const HandleTargets& targets, const Vertices& pose, Vertices* out,
                              const std::function<bool()>& cancel) {
  State& st = *state_;
  if (st.rest.rows() == 0) throw std::invalid_argument("Refiner::refine: call precompute first");
  if (out == nullptr) throw std::invalid_argument("Refiner::refine: out is null");
  if (pose.size() > 0) {
    ::qpreduce::check_size("Refiner::refine: pose rows", st.rest.rows(), pose.rows());
    ::qpreduce::check_finite("Refiner::refine: pose", pose);
  }
  const Vertices& input = pose.size() > 0 ? pose : st.rest;
  RefineSummary summary;
  if (!st.has_handles || !same_handles(handles, st.handles)) {
    st.has_handles = false;
    const HandleSetSummary hs = st.lg.set_handles(handles);
    summary.refactored = true;
    summary.setup_seconds = hs.seconds;
    if (!hs.ok()) {
      summary.status = hs.status;
      summary.message = "refine: " + hs.message;
      *out = input;
      return summary;
    }
    st.handles = handles;
    st.has_handles = true;
    st.axis_separable = hs.axis_separable;
  }
  summary.axis_separable = st.axis_separable;
  ReferenceSolution solution;
  const ReferenceSummary rs = st.lg.solve(targets, &solution, pose, cancel);
  summary.status = rs.status;
  summary.message = rs.message;
  summary.rounds = rs.iterations;
  summary.converged = rs.converged;
  summary.cancelled = rs.cancelled;
  summary.rejected_steps = rs.rejected_steps;
  summary.newton_steps = rs.newton_steps;
  summary.cg_iterations = rs.cg_iterations;
  summary.seconds = rs.solve_seconds;
  summary.initial_energy = rs.initial_energy;
  summary.energy = rs.energy;
  summary.fixed_point_residual = rs.fixed_point_residual;
  summary.estimated_distance = rs.estimated_distance;
  summary.handle_residual = rs.handle_residual;
  summary.round_energy = rs.round_energy;
  summary.round_seconds = rs.round_seconds;
  *out = std::move(solution.V);
  summary.arap_energy = arap_energy(st.rest, st.lg.elements(), *out);
  const Eigen::VectorXd d = (*out - input).rowwise().norm();
  summary.rms_from_input = std::sqrt(d.squaredNorm() / static_cast<double>(d.size())) / st.diagonal;
  summary.max_from_input = d.maxCoeff() / st.diagonal;
  return summary;
}

void RefineSummary::add_details(Report* out) const {
  out->add("rounds", rounds)
      .add("converged", converged)
      .add("cancelled", cancelled)
      .add("refactored", refactored)
      .add("axis_separable", axis_separable)
      .add("rejected_steps", rejected_steps)
      .add("newton_steps", newton_steps)
      .add("cg_iterations", cg_iterations)
      .add("seconds", seconds)
      .add("setup_seconds", setup_seconds)
      .add("initial_energy", initial_energy)
      .add("energy", energy)
      .add("arap_energy", arap_energy)
      .add("fixed_point_residual", fixed_point_residual)
      .add("estimated_distance", estimated_distance)
      .add("handle_residual", handle_residual)
      .add("rms_from_input", rms_from_input)
      .add("max_from_input", max_from_input);
}

}  // namespace qpreduce::deform
