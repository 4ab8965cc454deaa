#include "qpreduce/subspace_solver.h"

#include "blas.h"
#include "factored_operators.h"
#include "range_space.h"
#include "simd_kernels.h"
#include "subspace_internal.h"

#include "qp_operators.h"
#include "qpreduce/checks.h"
#include "qpreduce/util/timer.h"

#include <Eigen/Eigenvalues>
#include <Eigen/QR>
#include <fmt/format.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <limits>
#include <optional>
#include <type_traits>
#include <vector>

namespace qpreduce {

namespace {

using MatD = Matrix<double>;

// The O(n·p) passes (reduce_linear_term, reconstruct) stream the whole basis;
// below this many entries (n·p) one thread is faster than waking a team and
// is not exposed to a descheduled second thread on a shared machine.
constexpr Index kParallelEntries = Index(1) << 24;
// Rows per block of reconstruct: X's block and one panel of N stay in L2.
constexpr Index kReconstructRows = 2048;

// Sets to zero the entries of A_r = AᵀB (m × p) with |A_r(i,j)| ≤
// tau·‖a_i‖·‖B_j‖ (subspace_solver.h, "Round-off in A_r"); basis_norms holds
// ‖B_j‖. Returns the number of entries zeroed; *emptied counts the rows that
// had a nonzero entry and have none left.
template <typename Scalar>
Index drop_roundoff(const SparseMatrix<Scalar>& A, const Vector<double>& basis_norms, double tau, MatD* Ar,
                    Index* emptied) {
  const Index m = Ar->rows(), p = Ar->cols();
  Vector<double> cut(m);  // tau·‖a_i‖, O(nnz(A))
  for (Index i = 0; i < m; ++i) {
    double sq = 0.0;
    for (typename SparseMatrix<Scalar>::InnerIterator it(A, i); it; ++it) sq += double(it.value()) * double(it.value());
    cut(i) = tau * std::sqrt(sq);
  }
  std::vector<char> had(static_cast<size_t>(m), 0), kept(static_cast<size_t>(m), 0);
  Index dropped = 0;
  for (Index j = 0; j < p; ++j)
    for (Index i = 0; i < m; ++i) {
      double& v = (*Ar)(i, j);
      if (v == 0.0) continue;
      had[static_cast<size_t>(i)] = 1;
      if (std::abs(v) <= cut(i) * basis_norms(j)) {
        v = 0.0;
        ++dropped;
      } else {
        kept[static_cast<size_t>(i)] = 1;
      }
    }
  *emptied = 0;
  for (size_t i = 0; i < had.size(); ++i) *emptied += had[i] && !kept[i];
  return dropped;
}

}  // namespace

template <typename Scalar>
void SubspaceSolver<Scalar>::require_ready(const char* what) const {
  if (!ready_) {
    throw std::invalid_argument(std::string(what) + ": no subspace (precompute did not succeed)");
  }
}

template <typename Scalar>
void SubspaceSolver<Scalar>::require_constrained(const char* what) const {
  require_ready(what);
  if (!constrained_) throw std::invalid_argument(std::string(what) + ": call set_constraints first");
}

template <typename Scalar>
void SubspaceSolver<Scalar>::require_basis(const char* what) const {
  require_ready(what);
  if (!has_basis_) {
    throw std::invalid_argument(std::string(what) +
                                ": this solver holds no basis B = [N UD] (restored without it, or released); "
                                "form A_r = AᵀB with your copy of B and use the reduced calls");
  }
}

template <typename Scalar>
SubspaceSummary SubspaceSolver<Scalar>::precompute(const SparseMatrix<Scalar>& H, const SparseMatrix<Scalar>& C,
                                                   const SparseMatrix<Scalar>& D, const SubspaceOptions& options) {
  ready_ = constrained_ = false;
  detail::SubspaceExtras extras;
  SubspaceSummary summary = detail::build_subspace_with_extras(H, C, D, options, &subspace_, &extras);
  if (!summary.ok()) return summary;
  n_ = H.rows();
  d_ = subspace_.N.cols();
  k_ = subspace_.UD.cols();
  has_basis_ = true;
  // H_r = BᵀHB, from the build's blocked residual pass (subspace_internal.h).
  Hr_d_ = std::move(extras.Hr);
  BtD_d_ = std::move(extras.BtD);
  Hr_ = Hr_d_.template cast<Scalar>();
  BtD_ = BtD_d_.template cast<Scalar>();
  compute_basis_norms();
  prepare_fast_path(options);
  ready_ = true;
  return summary;
}

template <typename Scalar>
void SubspaceSolver<Scalar>::set_reduced(const char* what, Index p, Index k, Matrix<double> Hr, Matrix<double> BtD) {
  check_size(fmt::format("{}: H_r rows", what).c_str(), p, Hr.rows());
  check_size(fmt::format("{}: H_r cols", what).c_str(), p, Hr.cols());
  check_size(fmt::format("{}: BᵀD rows", what).c_str(), p, BtD.rows());
  check_size(fmt::format("{}: BᵀD cols", what).c_str(), k, BtD.cols());
  check_finite(fmt::format("{}: H_r", what).c_str(), Hr);
  check_finite(fmt::format("{}: BᵀD", what).c_str(), BtD);
  const double asym = (Hr - Hr.transpose()).norm();
  if (asym > 1e-12 * std::max(1.0, Hr.norm())) {
    throw std::invalid_argument(fmt::format("{}: H_r is not symmetric (‖H_r − H_rᵀ‖ = {:.3e})", what, asym));
  }
  Hr_d_ = std::move(Hr);
  BtD_d_ = std::move(BtD);
  Hr_ = Hr_d_.template cast<Scalar>();
  BtD_ = BtD_d_.template cast<Scalar>();
}

template <typename Scalar>
void SubspaceSolver<Scalar>::restore(VariationalSubspace<Scalar> subspace, Matrix<double> Hr, Matrix<double> BtD,
                                     const SubspaceOptions& options) {
  ready_ = constrained_ = false;
  const Index n = subspace.N.rows(), d = subspace.N.cols(), k = subspace.UD.cols();
  check_size("SubspaceSolver::restore: UD rows", n, subspace.UD.rows());
  if (d == 0) throw std::invalid_argument("SubspaceSolver::restore: N has no columns");
  check_finite("SubspaceSolver::restore: N", subspace.N);
  check_finite("SubspaceSolver::restore: UD", subspace.UD);
  set_reduced("SubspaceSolver::restore", d + k, k, std::move(Hr), std::move(BtD));
  subspace_ = std::move(subspace);
  n_ = n;
  d_ = d;
  k_ = k;
  has_basis_ = true;
  compute_basis_norms();
  prepare_fast_path(options);
  ready_ = true;
}

template <typename Scalar>
void SubspaceSolver<Scalar>::restore_without_basis(Index n, Index d, Vector<double> basis_norms, Matrix<double> Hr,
                                                   Matrix<double> BtD, const SubspaceOptions& options) {
  constexpr const char* what = "SubspaceSolver::restore_without_basis";
  ready_ = constrained_ = false;
  if (n < 1 || d < 1)
    throw std::invalid_argument(fmt::format("{}: need n ≥ 1 and d ≥ 1, got n = {}, d = {}", what, n, d));
  const Index p = Hr.rows();
  if (p < d)
    throw std::invalid_argument(fmt::format("{}: H_r is {} × {}, fewer than d = {} rows", what, p, Hr.cols(), d));
  check_size(fmt::format("{}: basis norms", what).c_str(), p, basis_norms.size());
  check_finite(fmt::format("{}: basis norms", what).c_str(), basis_norms);
  if (basis_norms.size() > 0 && basis_norms.minCoeff() < 0.0) {
    throw std::invalid_argument(fmt::format("{}: a negative basis column norm", what));
  }
  set_reduced(what, p, p - d, std::move(Hr), std::move(BtD));
  subspace_ = VariationalSubspace<Scalar>{};
  n_ = n;
  d_ = d;
  k_ = p - d;
  has_basis_ = false;
  basis_norms_ = std::move(basis_norms);
  prepare_fast_path(options);
  ready_ = true;
}

template <typename Scalar>
void SubspaceSolver<Scalar>::release_basis() {
  subspace_ = VariationalSubspace<Scalar>{};
  has_basis_ = false;
}

template <typename Scalar>
void SubspaceSolver<Scalar>::compute_basis_norms() {
  basis_norms_.resize(d_ + k_);
  for (Index j = 0; j < d_; ++j) basis_norms_(j) = subspace_.N.col(j).template cast<double>().norm();
  for (Index j = 0; j < k_; ++j) basis_norms_(d_ + j) = subspace_.UD.col(j).template cast<double>().norm();
}

template <typename Scalar>
void SubspaceSolver<Scalar>::prepare_fast_path(const SubspaceOptions& options) {
  static std::atomic<std::uint64_t> generations{0};
  generation_ = ++generations;
  lift_tolerance_ = options.reduced_lift_tolerance;
  range_.reset();
  P0_ = MatD();
  lift_btd_ = MatD();
  if (options.prepare_constraint_path) prepare_range_space();
}

template <typename Scalar>
void SubspaceSolver<Scalar>::prepare_range_space() {
  // T₂, T₃ for the factored fast path, which only the double solver takes.
  constexpr bool factored_terms = std::is_same_v<Scalar, double>;
  auto range =
      std::make_shared<detail::RangeSpace>(detail::prepare_range_space(Hr_d_, lift_tolerance_, factored_terms));
  P0_ = range->Minv0 * BtD_d_;
  if constexpr (factored_terms) lift_btd_ = range->lift_cols.transpose() * BtD_d_;
  range_ = std::move(range);
}

template <typename Scalar>
void SubspaceSolver<Scalar>::reference_operators(const MatD& Abar, const ConstraintOptions& options,
                                                 ConstraintSummary* summary, MatD* Mb_out, MatD* Mq_out,
                                                 MatD* MY_out) const {
  // The small QP in the scaled coordinates w̄ (w = D_s·w̄): Hessian D_s·H_r·D_s,
  // constraints Ā (m×p). Shared with the Phase 1 solver (src/qp_operators.h).
  const auto& Ds = range_->scale.asDiagonal();
  const MatD Hbar = Ds * Hr_d_ * Ds;
  const detail::QpOperators ops = detail::qp_operators(Hbar, Abar, options, summary);
  const MatD& Mq = ops.Mg;
  const MatD& Mb = ops.Mc;
  *Mq_out = Ds * Mq * Ds;
  *Mq_out = 0.5 * (*Mq_out + Mq_out->transpose()).eval();
  *Mb_out = Ds * Mb;
  *MY_out = *Mq_out * BtD_d_;
}

template <typename Scalar>
ConstraintSummary SubspaceSolver<Scalar>::set_constraints(const SparseMatrix<Scalar>& A,
                                                          const ConstraintOptions& options) {
  require_basis("SubspaceSolver::set_constraints");
  check_size("SubspaceSolver::set_constraints: A rows", n_, A.rows());
  check_finite("SubspaceSolver::set_constraints: A", A);
  const Timer timer;
  const Index d = this->d(), k = this->k(), p = d + k, m = A.cols();
  // A_r = AᵀB: nnz(A)·p work for sparse A.
  MatD Ar(m, p);
  {
    const detail::ScopedOmpThreads threads(options.threads);
    Ar.leftCols(d) = (A.transpose() * subspace_.N).template cast<double>();
    Ar.rightCols(k) = (A.transpose() * subspace_.UD).template cast<double>();
  }
  ConstraintSummary summary = set_constraints_reduced(A, std::move(Ar), options);
  summary.seconds = timer.seconds();
  return summary;
}

template <typename Scalar>
ConstraintSummary SubspaceSolver<Scalar>::set_constraints_reduced(const SparseMatrix<Scalar>& A, MatD Ar,
                                                                  const ConstraintOptions& options) {
  std::string why;
  if (!options.is_valid(&why)) throw std::invalid_argument("ConstraintOptions: " + why);
  require_ready("SubspaceSolver::set_constraints_reduced");
  check_size("SubspaceSolver::set_constraints_reduced: A rows", n_, A.rows());
  check_size("SubspaceSolver::set_constraints_reduced: A_r rows (A's columns)", A.cols(), Ar.rows());
  check_size("SubspaceSolver::set_constraints_reduced: A_r columns (p)", p(), Ar.cols());
  check_finite("SubspaceSolver::set_constraints_reduced: A", A);
  check_finite("SubspaceSolver::set_constraints_reduced: A_r", Ar);
  const Timer timer;
  const detail::ScopedOmpThreads threads(options.threads);
  constrained_ = false;
  // Round-off entries (CᵀN = I, CᵀUD = 0 hold only to round-off) to exact zeros.
  Index dropped = 0, emptied = 0;
  if (options.drop_tolerance > 0.0) dropped = drop_roundoff(A, basis_norms_, options.drop_tolerance, &Ar, &emptied);
  ConstraintSummary summary = apply_constraints(std::move(Ar), options);
  summary.dropped = dropped;
  if (emptied > 0) {
    summary.message += fmt::format(
        " ({} of them with every entry of A_r = AᵀB at most drop_tolerance = {:.1e} × ‖a_i‖‖B_j‖: no component in "
        "the subspace, the row is zero)",
        emptied, options.drop_tolerance);
  }
  summary.seconds = timer.seconds();
  return summary;
}

template <typename Scalar>
ConstraintSummary SubspaceSolver<Scalar>::set_constraints_in_design(const MatrixS& A_c,
                                                                    const ConstraintOptions& options) {
  std::string why;
  if (!options.is_valid(&why)) throw std::invalid_argument("ConstraintOptions: " + why);
  require_ready("SubspaceSolver::set_constraints_in_design");
  check_size("SubspaceSolver::set_constraints_in_design: A_c rows", d(), A_c.rows());
  check_finite("SubspaceSolver::set_constraints_in_design: A_c", A_c);
  const Timer timer;
  const detail::ScopedOmpThreads threads(options.threads);
  constrained_ = false;
  // A_r = A_cᵀ·Cᵀ[N UD] = [A_cᵀ 0]: CᵀN = I and CᵀUD = 0 (Eq. 4, second row).
  MatD Ar = MatD::Zero(A_c.cols(), p());
  Ar.leftCols(d()) = A_c.transpose().template cast<double>();
  ConstraintSummary summary = apply_constraints(std::move(Ar), options);
  summary.seconds = timer.seconds();
  return summary;
}

// The fast path's operators, in the range space: the factored form
// when `factored`, the explicit one otherwise; false when the range space
// refuses (rank, conditioning) and the reference path must form them.
template <typename Scalar>
bool SubspaceSolver<Scalar>::fast_operators(const MatD& Ar, const ConstraintOptions& options, bool factored,
                                            ConstraintSummary* summary_out, MatD* Mb_out, MatD* Mq_out,
                                            MatD* MY_out) {
  ConstraintSummary& summary = *summary_out;
  MatD &Mb = *Mb_out, &Mq = *Mq_out, &MY = *MY_out;
  const Index m = Ar.rows();
  // The BLAS runs single-threaded here unless the caller asked for more.
  std::optional<detail::ScopedBlasThreads> blas;
  if (options.threads > 0) blas.emplace(options.threads);
  detail::RangeSpaceOperators rso;
  if (factored) {
    if (detail::range_space_rank(*range_, Ar, options, &summary)) {
      const Eigen::SparseMatrix<double> At = Ar.transpose().sparseView(0.0, 0.0);  // exact zeros dropped
      // Copies of the solver share the operators: write into a fresh set when shared.
      if (!factored_ops_ || factored_ops_.use_count() > 1)
        factored_ops_ = std::make_shared<detail::FactoredOperators>();
      factored_ = detail::factored_operators(*range_, P0_, lift_btd_, At, options.soft, options.delta,
                                             options.rank_tolerance,
                                             (Ar * range_->scale.asDiagonal()).squaredNorm(),  // ‖Ā‖_F²
                                             factored_ops_.get());
    }
    return factored_;
  }
  if (detail::range_space_operators(*range_, Ar, options, &summary, &rso)) {
    // M_q = M_g (lower triangle), M_b = T's first m columns,
    // M_Y = P0 − T·(Y'ᵀBᵀD).
    Mq = std::move(rso.Mg);
    Mb = rso.T.leftCols(m);
    MY = P0_;
    if (k() > 0) {
      MatD YtBd(rso.Y.cols(), k());
      detail::blas_gemm(true, false, 1.0, rso.Y, BtD_d_, 0.0, YtBd);
      detail::blas_gemm(false, false, -1.0, rso.T, YtBd, 1.0, MY);
    }
    return Mb.allFinite() && MY.allFinite();
  }
  return false;
}

template <typename Scalar>
ConstraintSummary SubspaceSolver<Scalar>::apply_constraints(MatD Ar, const ConstraintOptions& options) {
  if (!range_) prepare_range_space();
  ConstraintSummary summary;
  const Index m = Ar.rows(), p = Ar.cols();
  summary.m = m;
  factored_ = false;
  // The operator form: multiply-adds of the factored form's sparse products
  // against the explicit form's GEMMs (ConstraintOptions::explicit_operators).
  const Index q = m + range_->lift_cols.cols();
  const double nz = static_cast<double>((Ar.array() != 0.0).count());
  const double pd = static_cast<double>(p), md = static_cast<double>(m);
  const double factored_madds = pd * nz + 3.0 * std::min(nz * nz, nz * (pd + md));
  const double explicit_madds = pd * pd * (md + 0.5 * static_cast<double>(q));
  const bool factored = std::is_same_v<Scalar, double> && !options.explicit_operators && q <= kMaxFactoredRank &&
                        options.factored_cost_ratio * factored_madds <= explicit_madds;
  // The operators are formed in double: in place for Scalar = double (no
  // p × p copy), in scratch that is cast afterwards otherwise.
  MatD scratch_b, scratch_q, scratch_y;
  MatD* Mb_out = &scratch_b;
  MatD* Mq_out = &scratch_q;
  MatD* MY_out = &scratch_y;
  if constexpr (std::is_same_v<Scalar, double>) {
    Mb_out = &Mb_;
    Mq_out = &Mq_;
    MY_out = &MY_;
  }
  MatD &Mb = *Mb_out, &Mq = *Mq_out, &MY = *MY_out;

  const bool fast = options.fast_path && fast_operators(Ar, options, factored, &summary, &Mb, &Mq, &MY);
  if (!fast) {
    summary = ConstraintSummary{};
    summary.m = m;
    const MatD Abar = Ar * range_->scale.asDiagonal();
    reference_operators(Abar, options, &summary, &Mb, &Mq, &MY);
    if (options.soft) summary.rank = detail::default_rank(Abar);
  }
  summary.fast_path = fast;
  summary.factored = factored_;

  if constexpr (std::is_same_v<Scalar, double>) {
    Ar_ = std::move(Ar);  // (passed by value: no copy; the operators were formed in place)
  } else {
    Ar_ = Ar.template cast<Scalar>();
    Mb_ = Mb.template cast<Scalar>();
    Mq_ = Mq.template cast<Scalar>();
    MY_ = MY.template cast<Scalar>();
  }
  m_ = m;
  constrained_ = true;
  return summary;
}

template <typename Scalar>
void SubspaceSolver<Scalar>::reduce_linear_term(const ConstRef& q, Ref q_r) const {
  require_basis("SubspaceSolver::reduce_linear_term");
  check_size("SubspaceSolver::reduce_linear_term: q size", n_, q.size());
  check_size("SubspaceSolver::reduce_linear_term: q_r size", p(), q_r.size());
  // Column dot products, OpenMP over column blocks of the basis.
  const Index d = this->d(), p = this->p();
  constexpr Index kCols = 8;
  const Index blocks = (p + kCols - 1) / kCols;
#pragma omp parallel for schedule(static) if (n_ * p > kParallelEntries)
  for (Index b = 0; b < blocks; ++b) {
    const Index j0 = b * kCols, j1 = std::min(p, j0 + kCols);
    for (Index j = j0; j < j1; ++j) q_r(j) = j < d ? subspace_.N.col(j).dot(q) : subspace_.UD.col(j - d).dot(q);
  }
}

template <typename Scalar>
void SubspaceSolver<Scalar>::reduce_linear_term_in_D(const ConstRef& Y, Ref q_r) const {
  require_ready("SubspaceSolver::reduce_linear_term_in_D");
  check_size("SubspaceSolver::reduce_linear_term_in_D: Y size", k(), Y.size());
  check_size("SubspaceSolver::reduce_linear_term_in_D: q_r size", p(), q_r.size());
  q_r.noalias() = BtD_ * Y;
}

template <typename Scalar>
void SubspaceSolver<Scalar>::solve(const ConstRef& b, const ConstRef& q_r, Ref w) const {
  assert(constrained_ && b.size() == m_ && q_r.size() == p() && w.size() == p());
  if constexpr (std::is_same_v<Scalar, double>) {
    if (factored_) {
      // w = M0·q_r + Y·(Σ⁻¹·([b; 0] − Yᵀq_r)); r and t live on the stack.
      const MatD& Y = factored_ops_->Y;
      const Index q = Y.cols();
      assert(q <= kMaxFactoredRank);
      double r_buf[kMaxFactoredRank], t_buf[kMaxFactoredRank];
      Eigen::Map<Eigen::VectorXd> r(r_buf, q);
      r.head(m_) = b;
      r.tail(q - m_).setZero();
      r.noalias() -= Y.transpose() * q_r;  // Eigen's row-major GEMV: no temporary for a contiguous q_r
      std::fill(t_buf, t_buf + q, 0.0);
      detail::symv_lower_add(factored_ops_->Sinv, r_buf, t_buf);
      std::fill(w.data(), w.data() + w.size(), 0.0);
      detail::symv_lower_add(range_->Minv0, q_r.data(), w.data());
      detail::gemv_add(Y.data(), Y.rows(), q, Y.outerStride(), t_buf, w.data());
      return;
    }
  }
  detail::gemv(Mb_, b.data(), w.data(), false);
  detail::symv_lower_add(Mq_, q_r.data(), w.data());
}

template <typename Scalar>
void SubspaceSolver<Scalar>::solve_in_D(const ConstRef& b, const ConstRef& Y, Ref w) const {
  assert(constrained_ && b.size() == m_ && Y.size() == k() && w.size() == p());
  if constexpr (std::is_same_v<Scalar, double>) {
    if (factored_) {
      // w = P0·Y + Yf·(Σ⁻¹[I_m; 0]·b − Φ·Y); t lives on the stack.
      const MatD& Yf = factored_ops_->Y;
      const MatD& Sinv = factored_ops_->Sinv;
      const MatD& PhiNeg = factored_ops_->PhiNeg;
      const Index q = Yf.cols();
      assert(q <= kMaxFactoredRank);
      double t_buf[kMaxFactoredRank];
      std::fill(t_buf, t_buf + q, 0.0);
      detail::gemv_add(Sinv.data(), q, m_, Sinv.outerStride(), b.data(), t_buf);
      detail::gemv_add(PhiNeg.data(), q, PhiNeg.cols(), PhiNeg.outerStride(), Y.data(), t_buf);
      detail::gemv(P0_, Y.data(), w.data(), false);
      detail::gemv_add(Yf.data(), Yf.rows(), q, Yf.outerStride(), t_buf, w.data());
      return;
    }
  }
  detail::gemv(Mb_, b.data(), w.data(), false);
  detail::gemv(MY_, Y.data(), w.data(), true);
}

template <typename Scalar>
void SubspaceSolver<Scalar>::reconstruct(const ConstRef& w, Ref X) const {
  require_basis("SubspaceSolver::reconstruct");
  check_size("SubspaceSolver::reconstruct: w size", p(), w.size());
  check_size("SubspaceSolver::reconstruct: X size", n_, X.size());
  // Row blocks, OpenMP: X_r = N_r·z + UD_r·y.
  const Index d = this->d(), k = this->k();
  const Index blocks = (n_ + kReconstructRows - 1) / kReconstructRows;
#pragma omp parallel for schedule(static) if (n_ * p() > kParallelEntries)
  for (Index b = 0; b < blocks; ++b) {
    const Index r = b * kReconstructRows, len = std::min(kReconstructRows, n_ - r);
    Scalar* x = X.data() + r;
    std::fill(x, x + len, Scalar(0));
    detail::gemv_add(subspace_.N.data() + r, len, d, subspace_.N.outerStride(), w.data(), x);
    detail::gemv_add(subspace_.UD.data() + r, len, k, subspace_.UD.outerStride(), w.data() + d, x);
  }
}

template class SubspaceSolver<double>;
template class SubspaceSolver<float>;

}  // namespace qpreduce
