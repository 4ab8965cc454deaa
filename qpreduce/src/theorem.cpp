#include "qpreduce/theorem.h"

#include "qpreduce/checks.h"
#include "qpreduce/util/timer.h"

#include "quotient_internal.h"

#include <Eigen/Dense>
#include <fmt/format.h>

#include <algorithm>
#include <cmath>

namespace qpreduce {

namespace {

// MatD, VecD, kInf, TruncatedSvd, truncated_svd, spectral_norm,
// require_options, ScopedThreads (quotient_internal.h).
using namespace detail;

}  // namespace

const char* to_string(TheoremStatus status) {
  switch (status) {
    case TheoremStatus::NotRun: return "not-run";
    case TheoremStatus::Applies: return "applies";
    case TheoremStatus::DoesNotApply: return "does-not-apply";
    case TheoremStatus::RankDeficientA: return "rank-deficient-A";
    case TheoremStatus::IndefiniteH: return "indefinite-H";
    case TheoremStatus::SolveFailed: return "solve-failed";
  }
  return "unknown";
}

// ---- Theorem 4.10 -----------------------------------------------------------------

TheoremBound theorem_bound(const WhitenedDesign& design, const CompanionDemand& demand,
                           const QuotientOptions& options) {
  require_options(options);
  const MatD& A = demand.A_hat;
  const Index r = A.rows(), m = A.cols();
  check_size("theorem_bound: A_hat rows", design.I_hat.rows(), r);
  check_size("theorem_bound: q_hat size", r, demand.q_hat.size());
  check_size("theorem_bound: b_hat size", m, demand.b_hat.size());
  const ScopedThreads threads(options.threads);
  TheoremBound t;
  t.r = r;
  t.m = m;
  const MatD& I_hat = design.I_hat;
  const VecD Iq = I_hat * demand.q_hat;
  t.norm_q_hat = demand.q_hat.norm();
  t.norm_b_hat = demand.b_hat.norm();
  t.q_residual = (Iq - demand.q_hat).norm();

  const TruncatedSvd s = truncated_svd(A, options.basis_tolerance);
  if (m > r || s.rank < m) {
    t.status = TheoremStatus::RankDeficientA;
    t.message = fmt::format("Â = (L⁺)ᵀA ({}×{}) has numerical rank {} < m = {}: Eq. 30 is not defined", r, m,
                            m > r ? std::min(s.rank, r) : s.rank, m);
    t.beta1 = t.beta2 = t.Delta = kInf;
    return t;
  }
  const MatD IA = I_hat * A;
  t.A_residual = spectral_norm(IA - A);
  if (m > 0) {
    t.norm_A_hat = s.sigma_max;
    t.norm_A_pinv = 1.0 / s.sigma_min;
    t.omega = s.sigma_max / s.sigma_min;
    // Â⁺(ÎÂ) = VΣ⁻¹Uᵀ(ÎÂ), m×m.
    const MatD M = s.V * (s.sigma.cwiseInverse().asDiagonal() * (s.U.transpose() * IA));
    t.rho = spectral_norm(MatD::Identity(m, m) - M);
  } else {
    t.omega = 1.0;  // no constraints: Eq. 30 and 35 reduce to q̂ and Îq̂
  }
  // Â_p = ÎÂ: rank relative to σ_max(Â).
  const TruncatedSvd sp = truncated_svd(IA, options.basis_tolerance, s.sigma_max);
  if (sp.rank == m) t.norm_Ap_pinv = m > 0 ? 1.0 / sp.sigma_min : 0.0;

  const double delta = t.A_residual;
  if (std::isfinite(t.norm_Ap_pinv)) {
    const double proj = std::min(1.0, delta * std::min(t.norm_A_pinv, t.norm_Ap_pinv));
    t.refined_bound = t.q_residual + proj * Iq.norm() + delta * t.norm_Ap_pinv * t.norm_Ap_pinv * t.norm_b_hat;
  }
  if (t.rho < 1.0) {
    t.beta1 = (2.0 - t.rho) / (1.0 - t.rho);
    t.beta2 = 1.0 + t.omega / (1.0 - t.rho);
    t.Delta = t.beta1 * t.norm_b_hat * t.norm_A_pinv * t.norm_A_pinv + t.beta2 * t.norm_q_hat * t.norm_A_pinv;
    t.bound = t.q_residual + t.Delta * delta;
    t.status = TheoremStatus::Applies;
    t.message = fmt::format("ρ = {:.3e}, ω = {:.3e}: bound {:.3e}", t.rho, t.omega, t.bound);
  } else {
    t.beta1 = t.beta2 = t.Delta = kInf;
    t.bound = kInf;
    t.status = TheoremStatus::DoesNotApply;
    t.message = fmt::format("ρ = ‖I − Â⁺ÎÂ‖₂ = {:.3e} ≥ 1: Theorem 4.10 does not apply (bound = +inf)", t.rho);
  }
  return t;
}

// ---- TheoremCheck ---------------------------------------------------------------------

bool TheoremCheck::practical_violation() const {
  return status == TheoremStatus::Applies && practical_error > bound.bound + slack;
}

bool TheoremCheck::theorem_violation() const {
  return status == TheoremStatus::Applies && theorem_error >= 0.0 && theorem_error > bound.bound + slack;
}

double TheoremCheck::eta() const { return practical_error > 0.0 ? bound.bound / practical_error : kInf; }

TheoremSetupSummary TheoremChecker::precompute(const SparseMatrix<double>& H, const SparseMatrix<double>& C,
                                               const SparseMatrix<double>& D, const QuotientOptions& options) {
  require_options(options);
  check_size("TheoremChecker::precompute: H cols", H.rows(), H.cols());
  check_size("TheoremChecker::precompute: C rows", H.rows(), C.rows());
  check_size("TheoremChecker::precompute: D rows", H.rows(), D.rows());
  check_finite("TheoremChecker::precompute: C", C);
  check_finite("TheoremChecker::precompute: D", D);
  const ScopedThreads threads(options.threads);
  const Timer timer;
  ready_ = false;
  options_ = options;
  TheoremSetupSummary s;
  s.factor = factor_psd(H, options, &factor_);
  if (!s.factor.ok()) {
    s.status = s.factor.status;
    s.message = s.factor.message;
    s.seconds = timer.seconds();
    return s;
  }
  H_ = MatD(H);
  design_ = whiten_design(factor_, MatD(C), MatD(D), options);
  s.design_rank = design_.rank;
  s.subspace = solver_.precompute(H, C, D, options.subspace);
  if (!s.subspace.ok()) {
    s.status = s.subspace.status;
    s.message = "engine subspace: " + s.subspace.message;
    s.seconds = timer.seconds();
    return s;
  }
  ready_ = true;
  s.status = Status::Success;
  s.message = fmt::format("{}; design rank {} of d + k = {}", s.factor.message, design_.rank,
                          C.cols() + D.cols());
  s.seconds = timer.seconds();
  return s;
}

TheoremCheck TheoremChecker::check(const SparseMatrix<double>& A, const Vector<double>& b, const Vector<double>& q,
                                   TheoremSolutions* solutions) {
  if (!ready_) throw std::invalid_argument("TheoremChecker::check: called before a successful precompute");
  const Index n = H_.rows(), m = A.cols();
  check_size("TheoremChecker::check: A rows", n, A.rows());
  check_size("TheoremChecker::check: b size", m, b.size());
  check_size("TheoremChecker::check: q size", n, q.size());
  check_finite("TheoremChecker::check: A", A);
  check_finite("TheoremChecker::check: b", b);
  check_finite("TheoremChecker::check: q", q);
  const ScopedThreads threads(options_.threads);
  const Timer timer;
  TheoremCheck out;
  auto fail = [&](std::string message) {
    out.status = TheoremStatus::SolveFailed;
    out.message = std::move(message);
    out.seconds = timer.seconds();
    return out;
  };

  const MatD Ad(A);
  VecD X_min, X_star;
  std::string failure = exact_solve(Ad, b, q, &X_min, &out.exact_kkt_residual);
  if (!failure.empty()) return fail(std::move(failure));
  failure = engine_solve(A, b, q, &X_star);
  if (!failure.empty()) return fail(std::move(failure));

  const VecD LX_min = factor_.L * X_min;
  const VecD LX_star = factor_.L * X_star;
  out.exact_norm = LX_min.norm();
  out.practical_error = (LX_star - LX_min).norm();
  out.practical_rel_error = X_min.norm() > 0.0 ? (X_star - X_min).norm() / X_min.norm() : (X_star - X_min).norm();

  CompanionDemand demand = companion_demand(factor_, Ad, b, q, X_min);
  out.bound = theorem_bound(design_, demand, options_);
  VecD X_hat_min, X_hat_star;
  if (companion_solution(demand, &X_hat_min, options_)) {
    out.closed_form_gap = (X_hat_min - LX_min).norm();
    if (subspace_companion_solution(design_, demand, &X_hat_star, options_)) {
      out.theorem_error = (X_hat_star - X_hat_min).norm();
      out.practical_gap = (LX_star - X_hat_star).norm();
    }
  }
  const double lambda_max = std::max(0.0, factor_.eigenvalues.size() ? factor_.eigenvalues.maxCoeff() : 0.0);
  out.slack = options_.roundoff_factor * static_cast<double>(n) * std::numeric_limits<double>::epsilon() *
              (out.exact_norm + std::sqrt(lambda_max) * X_min.norm());
  out.practical_covered = design_.kernel_in_design();
  out.status = out.bound.status;
  out.message = out.bound.message;
  if (solutions) {
    solutions->X_min = X_min;
    solutions->X_star = X_star;
    solutions->X_hat_min = X_hat_min;
    solutions->X_hat_star = X_hat_star;
    solutions->demand = std::move(demand);
  }
  out.seconds = timer.seconds();
  return out;
}

// Exact solution of Eq. 1: dense KKT [[H, A], [Aᵀ, 0]], LU with one step of
// iterative refinement.
std::string TheoremChecker::exact_solve(const Matrix<double>& A, const Vector<double>& b, const Vector<double>& q,
                                        Vector<double>* X_min, double* kkt_residual) const {
  const Index n = H_.rows(), m = A.cols();
  MatD K = MatD::Zero(n + m, n + m);
  K.topLeftCorner(n, n) = H_;
  K.topRightCorner(n, m) = A;
  K.bottomLeftCorner(m, n) = A.transpose();
  VecD rhs(n + m);
  rhs << q, b;
  const Eigen::PartialPivLU<MatD> lu(K);
  const double rcond = lu.rcond();
  if (!(rcond >= options_.kkt_rcond_tolerance)) {
    return fmt::format(
        "exact solve: the KKT matrix [[H, A], [Aᵀ, 0]] is singular to working precision (rcond {:.2e}): A "
        "must have full column rank and H must be positive definite on ker Aᵀ",
        rcond);
  }
  VecD sol = lu.solve(rhs);
  sol += lu.solve(rhs - K * sol);
  *kkt_residual = (K * sol - rhs).norm() / (K.norm() * sol.norm() + rhs.norm());
  *X_min = sol.head(n);
  return {};
}

// The engine's reduced answer X*: set_constraints, reduce, solve, reconstruct.
std::string TheoremChecker::engine_solve(const SparseMatrix<double>& A, const Vector<double>& b,
                                         const Vector<double>& q, Vector<double>* X_star) {
  const ConstraintSummary cs = solver_.set_constraints(A, options_.constraints);
  if (cs.status != Status::Success) return fmt::format("reduced solve: {} ({})", to_string(cs.status), cs.message);
  VecD q_r(solver_.p()), w(solver_.p());
  X_star->resize(H_.rows());
  solver_.reduce_linear_term(q, q_r);
  solver_.solve(b, q_r, w);
  solver_.reconstruct(w, *X_star);
  return {};
}

TheoremCheck check_theorem(const SparseMatrix<double>& H, const SparseMatrix<double>& C,
                           const SparseMatrix<double>& D, const SparseMatrix<double>& A,
                           const Vector<double>& b, const Vector<double>& q, const QuotientOptions& options,
                           TheoremSolutions* solutions) {
  TheoremChecker checker;
  const TheoremSetupSummary setup = checker.precompute(H, C, D, options);
  if (!setup.ok()) {
    TheoremCheck out;
    out.status = setup.status == Status::IndefiniteH ? TheoremStatus::IndefiniteH : TheoremStatus::SolveFailed;
    out.message = setup.message;
    out.seconds = setup.seconds;
    return out;
  }
  return checker.check(A, b, q, solutions);
}

void TheoremSetupSummary::add_details(Report* out) const {
  out->add("factor", factor.report())
      .add("subspace", subspace.report())
      .add("design_rank", design_rank)
      .add("seconds", seconds);
}

}  // namespace qpreduce
