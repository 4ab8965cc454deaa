// Phase 1 of the alternation (alternation.h): z = M_b·b + M_Y·Y for one
// constraint set, by the elimination of a selection (when A_z is one and it
// costs less), the range-space fast path on H_zz (FactoredPhaseOne) or the
// null-space method (ExplicitPhaseOne); phase_one.h has the forms.
#include "alternation_parts.h"

#include "blas.h"
#include "phase_one.h"
#include "qp_operators.h"
#include "range_space.h"

#include "qpreduce/checks.h"
#include "qpreduce/util/timer.h"

#include <Eigen/QR>
#include <fmt/format.h>

#include <memory>
#include <optional>

namespace qpreduce {

namespace detail {

Matrix<double> FactoredPhaseOne::MY() const {
  Matrix<double> MY = prep_->P0;
  blas_gemm(false, false, -1.0, T_, R_, 1.0, MY);
  return MY;
}

void FactoredPhaseOne::apply(const double* b, const double* Y, double* z, double* scratch) const {
  // z = M_b·b + P0·Y − T·(R·Y); scratch holds R·Y (μ).
  gemv(Mb_, b, z, false);
  gemv(prep_->P0, Y, z, true);
  gemv(R_, Y, scratch, false);
  for (Index i = 0; i < R_.rows(); ++i) scratch[i] = -scratch[i];
  gemv(T_, scratch, z, true);
}

namespace {

// G = NᵀD − H_zy (d × k): Phase 1's linear term per unit of Y.
Matrix<double> phase_one_G(const SubspaceSolver<double>& solver) {
  const Index d = solver.d(), k = solver.k();
  return solver.reduced_linear_map().topRows(d) - solver.reduced_hessian().topRightCorner(d, k);
}

// The fast path's per-solver part for `solver` (O(d³ + d²k)).
std::shared_ptr<const FixedCoordinatePrep> make_prep(const SubspaceSolver<double>& solver) {
  const Index d = solver.d(), k = solver.k();
  auto prep = std::make_shared<FixedCoordinatePrep>();
  prep->generation = solver.generation();
  prep->range = prepare_range_space(solver.reduced_hessian().topLeftCorner(d, d), solver.lift_tolerance());
  prep->G = phase_one_G(solver);
  prep->P0.resize(d, k);
  blas_gemm(false, false, 1.0, prep->range.Minv0, prep->G, 0.0, prep->P0);
  prep->LtG.resize(prep->range.lift_cols.cols(), k);
  blas_gemm(true, false, 1.0, prep->range.lift_cols, prep->G, 0.0, prep->LtG);
  return prep;
}

// The fast path for (A_z, A_y), or null when it does not apply (then the
// caller runs the null-space method). Sets *summary as range_space_operators.
std::shared_ptr<const PhaseOneOperator> fast_phase_one(const std::shared_ptr<const FixedCoordinatePrep>& prep,
                                                       const Matrix<double>& Az, const Matrix<double>& Ay,
                                                       const ConstraintOptions& options, ConstraintSummary* summary) {
  RangeSpaceOperators rso;
  if (!range_space_operators(prep->range, Az, options, summary, &rso)) return nullptr;
  // M_b = T's first m columns, M_Y = P0 − T·R with
  // R = Y'ᵀG + [A_y; 0] = [A_z·P0 + A_y; LᵀG] (M0 symmetric). M_Y stays
  // factored: forming it is d·μ·k multiply-adds and two passes over d × k.
  const Index m = Az.rows(), mu = rso.T.cols(), k = Ay.cols();
  Matrix<double> R(mu, k);
  R.topRows(m) = Ay;
  blas_gemm(false, false, 1.0, Az, prep->P0, 1.0, R.topRows(m));
  R.bottomRows(mu - m) = prep->LtG;
  if (!R.allFinite() || !rso.T.allFinite()) return nullptr;
  return std::make_shared<FactoredPhaseOne>(prep, std::move(rso.T), std::move(R), rso.Sinv.topRows(m));
}

// The null-space method on H_zz (qp_operators.h): M_b = M_c, M_Y = M_g·G − M_c·A_y.
// G: phase_one_G(solver).
std::shared_ptr<const PhaseOneOperator> null_space_phase_one(const SubspaceSolver<double>& solver,
                                                             const Matrix<double>& G, const Matrix<double>& Az,
                                                             const Matrix<double>& Ay,
                                                             const ConstraintOptions& options,
                                                             ConstraintSummary* summary) {
  const Index d = solver.d(), k = solver.k();
  QpOperators ops = qp_operators(solver.reduced_hessian().topLeftCorner(d, d), Az, options, summary);
  Matrix<double> MY(d, k);  // through the BLAS (blas.h)
  blas_gemm(false, false, 1.0, ops.Mg, G, 0.0, MY);
  blas_gemm(false, false, -1.0, ops.Mc, Ay, 1.0, MY);
  return std::make_shared<ExplicitPhaseOne>(std::move(ops.Mc), std::move(MY));
}

// The multipliers of an eliminated selection (hard): W = (A_zᵀ)⁺ keeps the
// rows C and divides by a, so with X = [M_b, M_Y] split into its rows C
// (X_C, m × (m + k); M_b's part is diag(1/a)) and F,
//     Λ_b = −diag(1/a)·(H_CC·diag(1/a) + H_CF·M_b,F),
//     Λ_y = diag(1/a)·(G_C − H_CC·M_Y,C − H_CF·M_Y,F),
// O(m·f·(m + k) + m²·k) instead of the dense W·H_zz·X's m·d·(m + k).
// Returns Λ_y (m × k) and sets *Lb.
Matrix<double> selection_multipliers(const SubspaceSolver<double>& solver, const PhaseOneOperator& op,
                                     const ScaledSelection& sel, Matrix<double>* Lb) {
  const Index d = solver.d(), m = static_cast<Index>(sel.cols.size()), f = d - m;
  const Matrix<double> MY = op.MY();
  const Index k = MY.cols();
  const auto H = solver.reduced_hessian().topLeftCorner(d, d);
  const Matrix<double> G = phase_one_G(solver);
  Matrix<double> Hcc(m, m), Hcf(m, f), Xf(f, m + k), MYc(m, k), out(m, m + k);
  for (Index i = 0; i < m; ++i) {
    const Index c = sel.cols[static_cast<size_t>(i)];
    for (Index j = 0; j < m; ++j) Hcc(j, i) = H(sel.cols[static_cast<size_t>(j)], c);
    MYc.row(i) = MY.row(c);
    out.row(i).tail(k) = G.row(c);
  }
  for (Index a = 0; a < f; ++a) {
    const Index r = sel.free[static_cast<size_t>(a)];
    for (Index j = 0; j < m; ++j) Hcf(j, a) = H(sel.cols[static_cast<size_t>(j)], r);
    Xf.row(a).head(m) = op.Mb().row(r);
    Xf.row(a).tail(k) = MY.row(r);
  }
  out.leftCols(m) = -(Hcc * sel.inv_scale.asDiagonal());
  blas_gemm(false, false, -1.0, Hcc, MYc, 1.0, out.rightCols(k));
  blas_gemm(false, false, -1.0, Hcf, Xf, 1.0, out);
  out = sel.inv_scale.asDiagonal() * out;
  *Lb = out.leftCols(m);
  return out.rightCols(k);
}

// The multipliers of Phase 1 as affine maps of (b, y) (alternation_parts.h,
// form_energy_terms), with z = M_b·b + M_Y·y:
//   fast path (hard or soft)  λ = K·(R·y − [b; 0]) (phase_one.h):
//         Λ_b = −K's first m columns, Λ_y = K·R; O(m·μ·k);
//   otherwise, hard  A_zᵀλ = G·y − H_zz·z (z-stationarity) → λ = W·(G·y − H_zz·z),
//         W = (A_zᵀ)⁺: Λ_b = −(W·H_zz)·M_b, Λ_y = W·G − (W·H_zz)·M_Y;
//   otherwise, soft  λ = 2δ·(A_z·z + A_y·y − b): Λ_b = 2δ·(A_z·M_b − I), Λ_y = 2δ·(A_z·M_Y + A_y).
// (With dependent hard rows λ is not unique, but (b − A_y·y)ᵀλ = (A_z·z)ᵀλ
// is, so the pseudo-inverse's λ serves.) O(m·d·(d + k)).
PhaseOneEnergy phase_one_energy(const SubspaceSolver<double>& solver, const PhaseOneOperator& op,
                                const Matrix<double>& Az, const Matrix<double>& Ay, const ConstraintOptions& options) {
  const Index m = Az.rows(), d = Az.cols(), k = Ay.cols();
  PhaseOneEnergy e;
  e.AyLy.resize(2 * m, k);
  if (m == 0) {  // no constraints: E(y) has no constraint term
    e.Lb.resize(0, 0);
    return e;
  }
  e.AyLy.topRows(m) = Ay;
  e.ay_zero = Ay.cwiseAbs().maxCoeff() == 0.0;
  if (const FactoredPhaseOne* fast = op.factored()) {
    e.Lb = -fast->K().leftCols(m);
    blas_gemm(false, false, 1.0, fast->K(), fast->R(), 0.0, e.AyLy.bottomRows(m));
    return e;
  }
  const Matrix<double> MY = op.MY();
  if (options.soft) {
    const double two_delta = 2.0 * options.delta;
    e.Lb = two_delta * (Az * op.Mb() - Matrix<double>::Identity(m, m));
    e.AyLy.bottomRows(m) = two_delta * (Az * MY + Ay);
    return e;
  }
  if (const ScaledSelection* sel = op.selection()) {
    e.AyLy.bottomRows(m) = selection_multipliers(solver, op, *sel, &e.Lb);
    return e;
  }
  const Matrix<double> W = Eigen::CompleteOrthogonalDecomposition<Matrix<double>>(Az.transpose()).pseudoInverse();
  const Matrix<double> WH = W * solver.reduced_hessian().topLeftCorner(d, d);
  e.Lb = -WH * op.Mb();
  e.AyLy.bottomRows(m) = W * phase_one_G(solver) - WH * MY;
  return e;
}

}  // namespace

}  // namespace detail

void detail::full_space_rows(const char* who, const SubspaceSolver<double>& solver, const SparseMatrix<double>& A,
                             Matrix<double>* Az, Matrix<double>* Ay) {
  if (!solver.ready()) throw std::invalid_argument(fmt::format("{}: the subspace solver is not ready", who));
  if (!solver.has_basis()) {
    throw std::invalid_argument(fmt::format(
        "{}: the subspace solver holds no basis B = [N UD] (restored without it, or released); form A_z, A_y "
        "with your copy of B and pass them",
        who));
  }
  check_size(fmt::format("{}: A rows", who).c_str(), solver.n(), A.rows());
  check_finite(fmt::format("{}: A", who).c_str(), A);
  *Az = A.transpose() * solver.subspace().N;
  *Ay = A.transpose() * solver.subspace().UD;
}

template <typename Scalar>
ConstraintSummary FixedCoordinateSolver<Scalar>::set_constraints(const SubspaceSolver<Scalar>& solver,
                                                                 const SparseMatrix<Scalar>& A,
                                                                 const ConstraintOptions& options) {
  // (set_reduced_constraints checks the options and the rest.)
  const Timer timer;
  Matrix<double> Az, Ay;
  detail::full_space_rows("FixedCoordinateSolver::set_constraints", solver, A, &Az, &Ay);
  ConstraintSummary summary = set_reduced_constraints(solver, Az, Ay, options);
  summary.seconds = timer.seconds();
  return summary;
}

template <typename Scalar>
ConstraintSummary FixedCoordinateSolver<Scalar>::set_reduced_constraints(const SubspaceSolver<Scalar>& solver,
                                                                         const Matrix<double>& Az,
                                                                         const Matrix<double>& Ay,
                                                                         const ConstraintOptions& options) {
  std::string why;
  if (!options.is_valid(&why)) throw std::invalid_argument("ConstraintOptions: " + why);
  if (!solver.ready()) {
    throw std::invalid_argument("FixedCoordinateSolver::set_reduced_constraints: the subspace solver is not ready");
  }
  check_size("FixedCoordinateSolver::set_reduced_constraints: A_z columns (d)", solver.d(), Az.cols());
  check_size("FixedCoordinateSolver::set_reduced_constraints: A_y columns (k)", solver.k(), Ay.cols());
  check_size("FixedCoordinateSolver::set_reduced_constraints: A_y rows (as A_z)", Az.rows(), Ay.rows());
  check_finite("FixedCoordinateSolver::set_reduced_constraints: A_z", Az);
  check_finite("FixedCoordinateSolver::set_reduced_constraints: A_y", Ay);
  const Timer timer;
  op_.reset();
  energy_.reset();  // the terms of the previous constraint set

  std::optional<detail::ScopedBlasThreads> blas;  // single-threaded BLAS unless asked (see ConstraintOptions)
  if (options.threads > 0) blas.emplace(options.threads);
  ConstraintSummary summary;
  summary.m = Az.rows();
  if (options.fast_path && !options.soft) {
    const bool prepared = prep_ && prep_->generation == solver.generation();
    if (auto sel = detail::scaled_selection(Az);
        sel && detail::elimination_pays(solver.d(), Az.rows(), Ay.cols(), prepared)) {
      op_ = detail::eliminated_phase_one(solver.reduced_hessian().topLeftCorner(solver.d(), solver.d()),
                                         prepared ? prep_->G : detail::phase_one_G(solver), Ay, std::move(*sel),
                                         options, &summary);
    }
  }
  if (!op_ && options.fast_path) {
    prepare_impl(solver);
    op_ = detail::fast_phase_one(prep_, Az, Ay, options, &summary);
  }
  if (!op_) {
    summary = ConstraintSummary{};
    // G as the fast path prepared it for this solver, when it did.
    if (prep_ && prep_->generation == solver.generation()) {
      op_ = detail::null_space_phase_one(solver, prep_->G, Az, Ay, options, &summary);
    } else {
      op_ = detail::null_space_phase_one(solver, detail::phase_one_G(solver), Az, Ay, options, &summary);
    }
  }
  scratch_.resize(op_->scratch_size());
  Az_ = Az;
  Ay_ = Ay;
  options_ = options;
  k_ = Ay.cols();
  summary.fast_path = op_->factored() != nullptr;
  summary.seconds = timer.seconds();
  return summary;
}

template <typename Scalar>
void FixedCoordinateSolver<Scalar>::form_energy_terms(const SubspaceSolver<Scalar>& solver) {
  if (!ready()) throw std::invalid_argument("FixedCoordinateSolver::form_energy_terms: no constraints set");
  if (!solver.ready() || solver.d() != d() || solver.k() != k()) {
    throw std::invalid_argument("FixedCoordinateSolver::form_energy_terms: not the solver the constraints were set for");
  }
  const detail::ScopedBlasThreads blas(options_.threads > 0 ? options_.threads : 1);
  energy_ = std::make_shared<const detail::PhaseOneEnergy>(
      detail::phase_one_energy(solver, *op_, Az_, Ay_, options_));
}

template <typename Scalar>
void FixedCoordinateSolver<Scalar>::prepare(const SubspaceSolver<Scalar>& solver) {
  if (!solver.ready()) throw std::invalid_argument("FixedCoordinateSolver::prepare: the subspace solver is not ready");
  const detail::ScopedBlasThreads blas(1);  // single-threaded BLAS, as set_constraints by default
  prepare_impl(solver);
}

template <typename Scalar>
void FixedCoordinateSolver<Scalar>::prepare_impl(const SubspaceSolver<Scalar>& solver) {
  if (prep_ && prep_->generation == solver.generation()) return;
  prep_ = detail::make_prep(solver);
}

template <typename Scalar>
const Matrix<Scalar>& FixedCoordinateSolver<Scalar>::Mb() const {
  static const Matrix<Scalar> empty;
  return op_ ? op_->Mb() : empty;
}

template <typename Scalar>
Matrix<Scalar> FixedCoordinateSolver<Scalar>::MY() const {
  return op_ ? op_->MY() : Matrix<Scalar>();
}

template <typename Scalar>
void FixedCoordinateSolver<Scalar>::solve(const ConstRef& b, const ConstRef& Y, Ref z) const {
  assert(ready() && b.size() == m() && Y.size() == k() && z.size() == d());
  op_->apply(b.data(), Y.data(), z.data(), scratch_.data());
}

template class FixedCoordinateSolver<double>;

}  // namespace qpreduce
