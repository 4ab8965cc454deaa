// FusedAlternation (alternation.h): Phase 1 folded into Phase 2's input,
// g = F_b·b + F_y·y, in the explicit or the factored form (fused_rounds.h).
// `set` forms the operators (fused_form.cpp); `run` picks one of the loops
// (fused_steps.h: plain, accelerated, second-order).
#include "alternation_parts.h"

#include "blas.h"
#include "fused_form.h"
#include "fused_rounds.h"
#include "fused_steps.h"
#include "phase_one.h"
#include "round_product.h"
#include "round_stop.h"
#include "simd_kernels.h"

#include "qpreduce/checks.h"

#include <fmt/format.h>

#include <omp.h>

#include <cmath>
#include <limits>
#include <memory>
#include <optional>

namespace qpreduce {

namespace {

using detail::FusedModel;
using detail::FusedWorkspace;
using MatD = Matrix<double>;

}  // namespace

template <typename Scalar>
FusedAlternation<Scalar>::FusedAlternation()
    : model_(std::make_unique<FusedModel>()), workspace_(std::make_unique<FusedWorkspace>()) {}

template <typename Scalar>
FusedAlternation<Scalar>::~FusedAlternation() = default;

template <typename Scalar>
FusedAlternation<Scalar>::FusedAlternation(const FusedAlternation& other)
    : model_(std::make_unique<FusedModel>(*other.model_)),
      workspace_(std::make_unique<FusedWorkspace>(*other.workspace_)) {}

template <typename Scalar>
FusedAlternation<Scalar>& FusedAlternation<Scalar>::operator=(const FusedAlternation& other) {
  if (this != &other) {
    *model_ = *other.model_;
    *workspace_ = *other.workspace_;
  }
  return *this;
}

// Moves swap, so that a moved-from object stays usable (and empty of nothing
// it did not have).
template <typename Scalar>
FusedAlternation<Scalar>::FusedAlternation(FusedAlternation&& other) noexcept
    : model_(std::make_unique<FusedModel>()), workspace_(std::make_unique<FusedWorkspace>()) {
  model_.swap(other.model_);
  workspace_.swap(other.workspace_);
}

template <typename Scalar>
FusedAlternation<Scalar>& FusedAlternation<Scalar>::operator=(FusedAlternation&& other) noexcept {
  model_.swap(other.model_);
  workspace_.swap(other.workspace_);
  return *this;
}

template <typename Scalar>
bool FusedAlternation<Scalar>::ready() const {
  return model_->ready;
}

template <typename Scalar>
bool FusedAlternation<Scalar>::factored() const {
  return model_->factored;
}

template <typename Scalar>
bool FusedAlternation<Scalar>::constrained_y() const {
  return model_->energy != nullptr;
}

template <typename Scalar>
bool FusedAlternation<Scalar>::second_order(const InputProjection<Scalar>& projection,
                                            const AlternationSettings& options) const {
  return model_->second_order && options.second_order && projection.rotation_blocks();
}

template <typename Scalar>
typename FusedAlternation<Scalar>::Path FusedAlternation<Scalar>::path(const InputProjection<Scalar>& projection,
                                                                        const AlternationSettings& options) const {
  if (second_order(projection, options)) return Path::SecondOrder;
  return options.anderson_window > 0 ? Path::Accelerated : Path::Plain;
}

template <typename Scalar>
const Vector<double>& FusedAlternation<Scalar>::proximal_weights() const {
  return model_->proximal;
}

template <typename Scalar>
void FusedAlternation<Scalar>::set_proximal_block_size(Index block) {
  if (block < 0) throw std::invalid_argument(fmt::format("FusedAlternation: proximal block size {} < 0", block));
  model_->block = block;
  model_->ready = false;
}

template <typename Scalar>
bool FusedAlternation<Scalar>::float_set() const {
  return model_->float_set;
}

template <typename Scalar>
const Matrix<Scalar>& FusedAlternation<Scalar>::Gz() const {
  return model_->Gz;
}

template <typename Scalar>
const Matrix<Scalar>& FusedAlternation<Scalar>::Gy() const {
  return model_->Gy;
}

template <typename Scalar>
void FusedAlternation<Scalar>::set(const FixedCoordinateSolver<Scalar>& phase1, const Matrix<Scalar>& Gz,
                                   const Matrix<Scalar>& Gy, int threads, FusedForm form, FusedPrecision precision) {
  set_impl(phase1, &Gz, &Gy, threads, form, precision);
}

template <typename Scalar>
void FusedAlternation<Scalar>::set(const FixedCoordinateSolver<Scalar>& phase1, int threads, FusedForm form,
                                   FusedPrecision precision) {
  if (!model_->inputs_ready) throw std::invalid_argument("FusedAlternation::set: no G_z, G_y given yet");
  set_impl(phase1, nullptr, nullptr, threads, form, precision);
}

// Gz, Gy: new inputs, or null for the kept ones (no comparison, no copy).
template <typename Scalar>
void FusedAlternation<Scalar>::set_impl(const FixedCoordinateSolver<Scalar>& phase1, const Matrix<Scalar>* Gz,
                                        const Matrix<Scalar>* Gy, int threads, FusedForm form,
                                        FusedPrecision precision) {
  FusedModel& M = *model_;
  std::optional<detail::ScopedBlasThreads> blas;  // single-threaded BLAS unless asked (see ConstraintOptions)
  if (threads > 0) blas.emplace(threads);
  if (!phase1.ready()) throw std::invalid_argument("FusedAlternation::set: Phase 1 has no constraints yet");
  const MatD& gz = Gz ? *Gz : M.Gz;
  const MatD& gy = Gy ? *Gy : M.Gy;
  check_size("FusedAlternation::set: G_z columns (d)", phase1.d(), gz.cols());
  check_size("FusedAlternation::set: G_y columns (k)", phase1.k(), gy.cols());
  check_size("FusedAlternation::set: G_y rows (as G_z)", gz.rows(), gy.rows());
  M.ready = false;
  M.factored = false;
  M.float_set = false;
  if (Gz) keep_inputs(M, *Gz, *Gy);
  const detail::PhaseOneEnergy* E = start_correction(M, phase1);
  const detail::FactoredPhaseOne* fast = phase1.phase_one_operator()->factored();
  if (fast) {
    form_c0(M, phase1.preparation(), M.Gz);
    const bool factored =
        form == FusedForm::Factored || (form == FusedForm::Automatic && M.Gz.rows() * M.Gy.cols() > kExplicitMaxEntries);
    set_fast_rounds(M, *fast, E, factored, precision);
  } else {
    set_explicit_plain(M, phase1, M.Gz, M.Gy, E);
    if (E) finish_correction(M, nullptr, nullptr);
  }
  // A stiff set takes second-order steps (run_second_order), which read the
  // explicit double F_y: an Automatic set that came out factored but stiff
  // is set again in the explicit form (once per set, O(q·k·μ)), up to
  // kSecondOrderMaxBlocks blocks (a step factors a 3d × 3d matrix).
  if (M.factored && fast != nullptr && form == FusedForm::Automatic && M.k() / 9 <= kSecondOrderMaxBlocks &&
      stiff_rotation_set(M)) {
    set_fast_rounds(M, *fast, start_correction(M, phase1), false, FusedPrecision::Double);
  }
  size_workspace(M, *workspace_);
  M.ready = true;
}

template <typename Scalar>
void FusedAlternation<Scalar>::prepare(const FixedCoordinateSolver<Scalar>& phase1, const Matrix<Scalar>& Gz,
                                       const Matrix<Scalar>& Gy, FusedPrecision precision) {
  check_size("FusedAlternation::prepare: G_y rows (as G_z)", Gz.rows(), Gy.rows());
  const auto& prep = phase1.preparation();
  if (prep) {
    check_size("FusedAlternation::prepare: G_z columns (d)", prep->G.rows(), Gz.cols());
    check_size("FusedAlternation::prepare: G_y columns (k)", prep->G.cols(), Gy.cols());
  }
  check_finite("FusedAlternation::prepare: G_z", Gz);
  check_finite("FusedAlternation::prepare: G_y", Gy);
  FusedModel& M = *model_;
  M.ready = false;
  keep_inputs(M, Gz, Gy);
  if (prep) {
    const detail::ScopedBlasThreads blas(1);
    form_c0(M, prep, M.Gz);
    if (precision == FusedPrecision::Float) form_gz_float(M, M.Gz);
    if (M.Gz.rows() * M.Gy.cols() > kExplicitMaxEntries) form_factored_base(M);
    if (M.Gy.rows() == M.Gy.cols()) form_curvature_test(M);
  }
}

template <typename Scalar>
AlternationResults FusedAlternation<Scalar>::run(const FixedCoordinateSolver<Scalar>& phase1,
                                                 InputProjection<Scalar>& projection,
                                                 const Eigen::Ref<const Vector<Scalar>>& b,
                                                 const AlternationSettings& options, Eigen::Ref<Vector<Scalar>> z,
                                                 Eigen::Ref<Vector<Scalar>> y) {
  const FusedModel& M = *model_;
  FusedWorkspace& W = *workspace_;
  if (!M.ready) throw std::invalid_argument("FusedAlternation::run: not set (call set after set_constraints or prepare)");
  check_size("FusedAlternation::run: b (m)", M.Fb.cols(), b.size());
  check_size("FusedAlternation::run: y (k)", M.k(), y.size());
  check_size("FusedAlternation::run: z (d)", phase1.d(), z.size());
  assert(options.is_valid(nullptr));
  if (M.float_set && !options.float_products) {
    throw std::invalid_argument(
        "FusedAlternation::run: set with FusedPrecision::Float needs float rounds "
        "(AlternationSettings::float_products)");
  }
  if (M.energy_seen != phase1.shared_energy_terms()) {
    throw std::invalid_argument(
        "FusedAlternation::run: Phase 1's energy terms changed after `set` (form_energy_terms before set, which "
        "reads them for constraints on y)");
  }
  if (M.energy && projection.proximal_block_size() != M.block) {
    throw std::invalid_argument(fmt::format(
        "FusedAlternation::run: the projection's proximal blocks ({}) are not those the rounds were set for ({}; "
        "set_proximal_block_size before set)",
        projection.proximal_block_size(), M.block));
  }
  projection.set_proximal_weights(M.proximal);
  const detail::StopTest stop(options);  // the budget counts from here
  // The products go through the run-time dispatched AVX2/FMA kernels
  // (simd_kernels.h) when the CPU has them.
  detail::gemv(M.Fb, b.data(), W.gb.data(), false);
  const Index q = M.q(), k = M.k(), block = projection.block_size();
  const int threads = options.threads > 0 ? options.threads : omp_get_max_threads();
  const bool parallel = threads > 1 && block > 0 && !omp_in_parallel() && q == k && q % block == 0 &&
                        q * k >= options.parallel_min_entries && q / block >= 2;
  AlternationResults summary;
  switch (path(projection, options)) {
    case Path::SecondOrder:
      prepare_second_order(phase1, k, W);
      summary = run_second_order(M, W, projection, *phase1.energy_terms(), b, options, stop, y);
      break;
    case Path::Accelerated:
      prepare_acceleration(phase1, projection, options, y, W);
      summary = run_accelerated(M, W, projection, *phase1.energy_terms(), b, options, stop, y);
      break;
    case Path::Plain:
      summary = parallel ? run_parallel(M, W, projection, options, stop, std::min<Index>(threads, q / block), block, y)
                         : run_serial(M, W, projection, options, stop, y);
      break;
  }
  phase1.solve(b, y, z);
  summary.status = Status::Success;
  return summary;
}

template <typename Scalar>
double FusedAlternation<Scalar>::energy(const FixedCoordinateSolver<Scalar>& phase1,
                                        InputProjection<Scalar>& projection,
                                        const Eigen::Ref<const Vector<Scalar>>& b,
                                        const Eigen::Ref<const Vector<Scalar>>& y, double* slack) {
  const FusedModel& M = *model_;
  FusedWorkspace& W = *workspace_;
  if (!M.ready) throw std::invalid_argument("FusedAlternation::energy: not set (call set first)");
  check_size("FusedAlternation::energy: b (m)", M.Fb.cols(), b.size());
  check_size("FusedAlternation::energy: y (k)", M.k(), y.size());
  if (!phase1.has_energy_terms() || !std::isfinite(projection.quadratic_term(y))) {
    return std::numeric_limits<double>::quiet_NaN();
  }
  projection.set_proximal_weights(M.proximal);
  const detail::PhaseOneEnergy& E = *phase1.energy_terms();
  const bool corrected = M.energy != nullptr;
  detail::size_energy_workspace(M.k(), phase1.m(), W);
  detail::gemv(M.Fb, b.data(), W.gb.data(), false);
  detail::constraint_term(E, b, corrected, W);
  detail::double_product(M, W, y.data(), 0, M.q(), W.scratch.data());
  double bound = 0.0;
  const double e = detail::reduced_energy(E, W, projection, b, y, true, corrected ? &M.proximal_entries : nullptr, &bound);
  if (slack) *slack = bound;
  return e;
}

template class FusedAlternation<double>;

}  // namespace qpreduce
