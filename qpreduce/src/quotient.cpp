#include "qpreduce/quotient.h"

#include "qpreduce/support.h"

#include <Eigen/Dense>
#include <fmt/format.h>
#include <omp.h>

#include <algorithm>
#include <cassert>
#include <cmath>

namespace qpreduce {

namespace {

using MatD = Matrix<double>;
using VecD = Vector<double>;
constexpr double kInf = std::numeric_limits<double>::infinity();

// Thin SVD truncated at tolerance·σ_max: M = U·diag(σ)·Vᵀ with `rank` columns.
struct TruncatedSvd {
  MatD U;          // rows × rank
  VecD sigma;      // rank
  MatD V;          // cols × rank
  Index rank = 0;
  double sigma_max = 0.0;
  double sigma_min = 0.0;  // smallest of min(rows, cols) singular values (0 if cols > rows)
};

TruncatedSvd truncated_svd(const MatD& M, double tolerance, double reference = -1.0) {
  TruncatedSvd s;
  if (M.rows() == 0 || M.cols() == 0) {
    s.U.resize(M.rows(), 0);
    s.V.resize(M.cols(), 0);
    return s;
  }
  Eigen::JacobiSVD<MatD> svd(M, Eigen::ComputeThinU | Eigen::ComputeThinV);
  const VecD& sv = svd.singularValues();
  s.sigma_max = sv(0);
  s.sigma_min = M.cols() > M.rows() ? 0.0 : sv(sv.size() - 1);
  // Rank relative to `reference` when given (e.g. σ_max(Â) for Â_p = ÎÂ).
  const double threshold = tolerance * (reference >= 0.0 ? reference : s.sigma_max);
  while (s.rank < sv.size() && sv(s.rank) > threshold) ++s.rank;
  s.U = svd.matrixU().leftCols(s.rank);
  s.V = svd.matrixV().leftCols(s.rank);
  s.sigma = sv.head(s.rank);
  return s;
}

double spectral_norm(const MatD& M) {
  if (M.size() == 0) return 0.0;
  return Eigen::JacobiSVD<MatD>(M).singularValues()(0);
}

void check_dense_symmetric(const char* what, const MatD& H, double tolerance) {
  const double asym = (H - H.transpose()).norm();
  const double scale = H.norm();
  if (asym > tolerance * scale) {
    throw std::invalid_argument(fmt::format("{}: not symmetric (‖H − Hᵀ‖_F = {:.3e} > {:.1e}·‖H‖_F = {:.3e})",
                                            what, asym, tolerance, tolerance * scale));
  }
}

void require_options(const QuotientOptions& options) {
  std::string why;
  if (!options.is_valid(&why)) throw std::invalid_argument("QuotientOptions: " + why);
}

// Sets this thread's OpenMP team size (read by Eigen's products and by the
// engine) for the scope; 0 leaves it unchanged.
class ScopedThreads {
 public:
  explicit ScopedThreads(int threads) : previous_(omp_get_max_threads()) {
    if (threads > 0) omp_set_num_threads(threads);
  }
  ~ScopedThreads() { omp_set_num_threads(previous_); }
  ScopedThreads(const ScopedThreads&) = delete;
  ScopedThreads& operator=(const ScopedThreads&) = delete;

 private:
  int previous_;
};

}  // namespace

// ---- options ------------------------------------------------------------------

bool QuotientOptions::is_valid(std::string* why) const {
  auto fail = [why](const std::string& msg) {
    if (why) *why = msg;
    return false;
  };
  if (!(rank_tolerance > 0.0 && rank_tolerance < 1.0)) return fail("rank_tolerance must lie in (0, 1)");
  if (!(symmetry_tolerance >= 0.0 && symmetry_tolerance < 1.0))
    return fail("symmetry_tolerance must lie in [0, 1)");
  if (!(basis_tolerance > 0.0 && basis_tolerance < 1.0)) return fail("basis_tolerance must lie in (0, 1)");
  if (!(kkt_rcond_tolerance >= 0.0 && kkt_rcond_tolerance < 1.0))
    return fail("kkt_rcond_tolerance must lie in [0, 1)");
  if (!(roundoff_factor >= 0.0 && std::isfinite(roundoff_factor)))
    return fail("roundoff_factor must be finite and ≥ 0");
  if (threads < 0) return fail("threads must be ≥ 0");
  std::string inner;
  if (!subspace.is_valid(&inner)) return fail("subspace: " + inner);
  if (!constraints.is_valid(&inner)) return fail("constraints: " + inner);
  return true;
}

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

// ---- H = LᵀL ---------------------------------------------------------------------

Matrix<double> PsdFactor::whiten(const Matrix<double>& M) const {
  assert(M.rows() == n());
  return L_pinv.transpose() * M;
}

Vector<double> PsdFactor::null_part(const Vector<double>& X) const {
  assert(X.size() == n());
  return kernel * (kernel.transpose() * X);
}

double PsdFactor::distance(const Vector<double>& x, const Vector<double>& y) const {
  assert(x.size() == n() && y.size() == n());
  return (L * (x - y)).norm();
}

FactorSummary factor_psd(const Matrix<double>& H, const QuotientOptions& options, PsdFactor* out) {
  require_options(options);
  if (!out) throw std::invalid_argument("factor_psd: out must not be null");
  check_size("factor_psd: H cols", H.rows(), H.cols());
  check_finite("factor_psd: H", H);
  check_dense_symmetric("factor_psd: H", H, options.symmetry_tolerance);
  const ScopedThreads threads(options.threads);
  const Timer timer;
  *out = PsdFactor{};
  FactorSummary s;
  const Index n = H.rows();
  s.n = n;

  Eigen::SelfAdjointEigenSolver<MatD> es(0.5 * (H + H.transpose()));
  if (es.info() != Eigen::Success) {
    s.status = Status::NumericalFailure;
    s.message = "factor_psd: the symmetric eigensolver did not converge";
    s.seconds = timer.seconds();
    return s;
  }
  const VecD& lambda = es.eigenvalues();  // ascending
  const double scale = n > 0 ? lambda.cwiseAbs().maxCoeff() : 0.0;
  const double threshold = options.rank_tolerance * scale;
  s.lambda_max = n > 0 ? lambda(n - 1) : 0.0;
  s.lambda_min = n > 0 ? lambda(0) : 0.0;
  if (n > 0 && lambda(0) < -threshold) {
    s.status = Status::IndefiniteH;
    s.message = fmt::format("H is indefinite: λ_min = {:.3e} < −rank_tolerance·max|λ| = {:.3e} (λ_max = {:.3e})",
                            lambda(0), -threshold, s.lambda_max);
    s.seconds = timer.seconds();
    return s;
  }
  Index r = 0;
  for (Index i = n - 1; i >= 0 && lambda(i) > threshold; --i) ++r;
  const Index nullity = n - r;
  const MatD& V = es.eigenvectors();
  const VecD root = lambda.tail(r).cwiseSqrt();
  out->L = root.asDiagonal() * V.rightCols(r).transpose();
  out->L_pinv = V.rightCols(r) * root.cwiseInverse().asDiagonal();
  out->kernel = V.leftCols(nullity);
  out->eigenvalues = lambda;

  s.rank = r;
  s.nullity = nullity;
  s.lambda_min_kept = r > 0 ? lambda(nullity) : 0.0;
  const double hnorm = H.norm();
  s.residual = hnorm > 0.0 ? (H - out->L.transpose() * out->L).norm() / hnorm : 0.0;
  s.status = Status::Success;
  s.message = fmt::format("H = LᵀL: n = {}, rank {}, nullity {}, λ ∈ [{:.3e}, {:.3e}]", n, r, nullity,
                          s.lambda_min_kept, s.lambda_max);
  s.seconds = timer.seconds();
  return s;
}

FactorSummary factor_psd(const SparseMatrix<double>& H, const QuotientOptions& options, PsdFactor* out) {
  require_options(options);
  check_size("factor_psd: H cols", H.rows(), H.cols());
  check_finite("factor_psd: H", H);
  check_symmetric("factor_psd: H", H, options.symmetry_tolerance);
  return factor_psd(MatD(H), options, out);
}

double h_distance(const SparseMatrix<double>& H, const Vector<double>& x, const Vector<double>& y) {
  check_size("h_distance: H cols", H.rows(), H.cols());
  check_size("h_distance: x size", H.rows(), x.size());
  check_size("h_distance: y size", H.rows(), y.size());
  const VecD v = x - y;
  return std::sqrt(std::max(0.0, v.dot(H * v)));
}

// ---- whitening -----------------------------------------------------------------------

WhitenedDesign whiten_design(const PsdFactor& factor, const Matrix<double>& C, const Matrix<double>& D,
                             const QuotientOptions& options) {
  require_options(options);
  check_size("whiten_design: C rows", factor.n(), C.rows());
  check_size("whiten_design: D rows", factor.n(), D.rows());
  check_finite("whiten_design: C", C);
  check_finite("whiten_design: D", D);
  const ScopedThreads threads(options.threads);
  const Index r = factor.rank(), d = C.cols(), k = D.cols();
  WhitenedDesign w;
  w.C_hat = factor.whiten(C);
  w.D_hat = factor.whiten(D);

  MatD CD(r, d + k);
  CD << w.C_hat, w.D_hat;
  const TruncatedSvd span = truncated_svd(CD, options.basis_tolerance);
  w.basis = span.U;
  w.rank = span.rank;
  w.I_hat = w.basis * w.basis.transpose();

  // Ĉ = U_C Σ V_Cᵀ:  ĈĈ⁺ = U_C U_Cᵀ,  (Ĉ⁺)ᵀ = U_C Σ⁻¹ V_Cᵀ.
  const TruncatedSvd c = truncated_svd(w.C_hat, options.basis_tolerance);
  w.rank_C_hat = c.rank;
  w.U_hat = MatD::Identity(r, r) - c.U * c.U.transpose();
  w.N_hat = c.U * c.sigma.cwiseInverse().asDiagonal() * c.V.transpose();
  if (w.N_hat.size() == 0) w.N_hat = MatD::Zero(r, d);
  w.UD_hat = w.U_hat * w.D_hat;

  if (factor.nullity() > 0) {
    MatD design(C.rows(), d + k);
    design << C, D;
    const TruncatedSvd span_cd = truncated_svd(design, options.basis_tolerance);
    const MatD& K = factor.kernel;
    w.kernel_angle = spectral_norm(K - span_cd.U * (span_cd.U.transpose() * K));
  }
  return w;
}

CompanionDemand companion_demand(const PsdFactor& factor, const Matrix<double>& A, const Vector<double>& b,
                                 const Vector<double>& q, const Vector<double>& X_min) {
  check_size("companion_demand: A rows", factor.n(), A.rows());
  check_size("companion_demand: b size", A.cols(), b.size());
  check_size("companion_demand: q size", factor.n(), q.size());
  check_size("companion_demand: X_min size", factor.n(), X_min.size());
  check_finite("companion_demand: A", A);
  check_finite("companion_demand: b", b);
  check_finite("companion_demand: q", q);
  check_finite("companion_demand: X_min", X_min);
  CompanionDemand c;
  c.A_hat = factor.whiten(A);
  c.q_hat = factor.whiten(q);
  c.X_bar = factor.null_part(X_min);
  c.b_hat = b - A.transpose() * c.X_bar;
  return c;
}

bool companion_solution(const CompanionDemand& demand, Vector<double>* X_hat, const QuotientOptions& options) {
  require_options(options);
  const MatD& A = demand.A_hat;
  check_size("companion_solution: q_hat size", A.rows(), demand.q_hat.size());
  check_size("companion_solution: b_hat size", A.cols(), demand.b_hat.size());
  if (A.cols() > A.rows()) return false;
  const TruncatedSvd s = truncated_svd(A, options.basis_tolerance);
  if (s.rank < A.cols()) return false;
  // (I − ÂÂ⁺)q̂ + (Â⁺)ᵀb̂ with ÂÂ⁺ = UUᵀ and (Â⁺)ᵀ = UΣ⁻¹Vᵀ.
  *X_hat = demand.q_hat - s.U * (s.U.transpose() * demand.q_hat) +
           s.U * (s.sigma.cwiseInverse().asDiagonal() * (s.V.transpose() * demand.b_hat));
  return true;
}

bool subspace_companion_solution(const WhitenedDesign& design, const CompanionDemand& demand,
                                 Vector<double>* X_hat, const QuotientOptions& options) {
  require_options(options);
  const MatD& A = demand.A_hat;
  check_size("subspace_companion_solution: A_hat rows", design.I_hat.rows(), A.rows());
  check_size("subspace_companion_solution: q_hat size", A.rows(), demand.q_hat.size());
  check_size("subspace_companion_solution: b_hat size", A.cols(), demand.b_hat.size());
  if (A.cols() > A.rows()) return false;
  const MatD Ap = design.I_hat * A;
  const TruncatedSvd s = truncated_svd(Ap, options.basis_tolerance, spectral_norm(A));
  if (s.rank < A.cols()) return false;
  // (Î − Â_pÂ_p⁺)q̂ + (Â_p⁺)ᵀb̂.
  *X_hat = design.I_hat * demand.q_hat - s.U * (s.U.transpose() * demand.q_hat) +
           s.U * (s.sigma.cwiseInverse().asDiagonal() * (s.V.transpose() * demand.b_hat));
  return true;
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

  // Exact solution of Eq. 1: dense KKT, LU with one step of iterative refinement.
  const MatD Ad(A);
  MatD K = MatD::Zero(n + m, n + m);
  K.topLeftCorner(n, n) = H_;
  K.topRightCorner(n, m) = Ad;
  K.bottomLeftCorner(m, n) = Ad.transpose();
  VecD rhs(n + m);
  rhs << q, b;
  const Eigen::PartialPivLU<MatD> lu(K);
  const double rcond = lu.rcond();
  if (!(rcond >= options_.kkt_rcond_tolerance)) {
    return fail(fmt::format(
        "exact solve: the KKT matrix [[H, A], [Aᵀ, 0]] is singular to working precision (rcond {:.2e}): A "
        "must have full column rank and H must be positive definite on ker Aᵀ",
        rcond));
  }
  VecD sol = lu.solve(rhs);
  sol += lu.solve(rhs - K * sol);
  out.exact_kkt_residual = (K * sol - rhs).norm() / (K.norm() * sol.norm() + rhs.norm());
  const VecD X_min = sol.head(n);

  // The engine's reduced answer X* (set_constraints, reduce, solve, reconstruct).
  const ConstraintSummary cs = solver_.set_constraints(A, options_.constraints);
  if (cs.status != Status::Success) {
    return fail(fmt::format("reduced solve: {} ({})", to_string(cs.status), cs.message));
  }
  VecD q_r(solver_.p()), w(solver_.p()), X_star(n);
  solver_.reduce_linear_term(q, q_r);
  solver_.solve(b, q_r, w);
  solver_.reconstruct(w, X_star);

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

}  // namespace qpreduce
