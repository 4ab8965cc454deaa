#include "qpreduce/quotient.h"

#include "qpreduce/checks.h"
#include "qpreduce/util/timer.h"

#include "quotient_internal.h"

#include <Eigen/Dense>
#include <fmt/format.h>

#include <algorithm>
#include <cassert>
#include <cmath>

namespace qpreduce {

namespace {

using namespace detail;  // the dense helpers of quotient_internal.h

void check_dense_symmetric(const char* what, const MatD& H, double tolerance) {
  const double asym = (H - H.transpose()).norm();
  const double scale = H.norm();
  if (asym > tolerance * scale) {
    throw std::invalid_argument(fmt::format("{}: not symmetric (‖H − Hᵀ‖_F = {:.3e} > {:.1e}·‖H‖_F = {:.3e})",
                                            what, asym, tolerance, tolerance * scale));
  }
}

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
  if (H.rows() == 0) throw std::invalid_argument("factor_psd: H is empty (n = 0)");
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
  if (H.rows() == 0) throw std::invalid_argument("factor_psd: H is empty (n = 0)");
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

void FactorSummary::add_details(Report* out) const {
  out->add("n", n)
      .add("rank", rank)
      .add("nullity", nullity)
      .add("lambda_max", lambda_max)
      .add("lambda_min", lambda_min)
      .add("lambda_min_kept", lambda_min_kept)
      .add("residual", residual)
      .add("seconds", seconds);
}

}  // namespace qpreduce
