#include "qpreduce/subspace.h"

#include "qpreduce/detail/dense.h"
#include "qpreduce/detail/timer.h"

#include <Eigen/Eigenvalues>
#include <fmt/format.h>

#include <algorithm>
#include <cmath>

namespace qpreduce {

bool SubspaceOptions::is_valid(std::string* why) const {
  auto fail = [why](const std::string& msg) {
    if (why) *why = msg;
    return false;
  };
  if (!(rho_scale > 0.0) || !std::isfinite(rho_scale)) return fail("rho_scale must be positive and finite");
  if (!(max_augmentation_fill > 0.0)) return fail("max_augmentation_fill must be positive");
  if (block_size < 1) return fail("block_size must be at least 1");
  if (!(symmetry_tolerance >= 0.0)) return fail("symmetry_tolerance must be non-negative");
  if (!(psd_shift > 0.0)) return fail("psd_shift must be positive");
  if (!(rank_tolerance > 0.0 && rank_tolerance < 1.0)) return fail("rank_tolerance must lie in (0, 1)");
  if (!(max_probe_error > 0.0)) return fail("max_probe_error must be positive");
  return true;
}

std::string SubspaceSummary::report() const {
  return fmt::format("{}: {} (n={}, d={}, k={}, backend={}, rho={:.3g}, kkt_residual={:.2e}, {:.3f} s)",
                     to_string(status), message, n, d, k, to_string(backend_used), rho,
                     kkt_residual, total_seconds);
}

namespace {

using SpD = SparseMatrix<double>;
using MatD = Matrix<double>;

SpD kkt_matrix(const SpD& H, const SpD& C) {
  const Index n = H.rows(), d = C.cols();
  std::vector<Eigen::Triplet<double>> t;
  t.reserve(H.nonZeros() + 2 * C.nonZeros());
  for (Index j = 0; j < n; ++j)
    for (SpD::InnerIterator it(H, j); it; ++it) t.emplace_back(it.row(), j, it.value());
  for (Index j = 0; j < d; ++j)
    for (SpD::InnerIterator it(C, j); it; ++it) {
      t.emplace_back(it.row(), n + j, it.value());
      t.emplace_back(n + j, it.row(), it.value());
    }
  SpD K(n + d, n + d);
  K.setFromTriplets(t.begin(), t.end());
  return K;
}

// Relative residual of Eq. 4 for B = [N UD]; see SubspaceSummary::kkt_residual.
double kkt_residual(const SpD& H, const SpD& C, const SpD& D, const MatD& B) {
  const Index d = C.cols(), k = D.cols();
  MatD R1 = H * B;
  if (k > 0) R1.rightCols(k) -= MatD(D);
  const MatD CtC = MatD(C.transpose() * C);
  const MatD coef = CtC.ldlt().solve(MatD(C.transpose() * R1));
  R1.noalias() -= C * coef;
  MatD R2 = C.transpose() * B;
  R2.leftCols(d) -= MatD::Identity(d, d);
  const double scale1 = H.norm() * B.norm() + D.norm();
  const double scale2 = C.norm() * B.norm();
  const double r1 = scale1 > 0 ? R1.norm() / scale1 : R1.norm();
  const double r2 = scale2 > 0 ? R2.norm() / scale2 : R2.norm();
  return std::max(r1, r2);
}

// Solves K·x = K·v for a random v and returns ‖x − v‖/‖v‖: a direct measure of
// whether the factorization can be trusted (near-singular factors that slipped
// through a tiny pivot give O(1) errors along their null vectors).
double probe_error(const SparseFactorization& factor, const SpD& K) {
  Eigen::VectorXd v(K.rows());
  for (Index i = 0; i < v.size(); ++i) v(i) = std::sin(1.0 + 0.7 * static_cast<double>(i));  // deterministic
  MatD x = K.selfadjointView<Eigen::Lower>() * v;
  if (factor.backend() == Backend::SparseLU) x = K * v;
  factor.solveInPlace(x, 1);
  const double err = (x.col(0) - v).norm() / v.norm();
  return std::isfinite(err) ? err : INFINITY;
}

}  // namespace

template <typename Scalar>
SubspaceSummary build_subspace(const SparseMatrix<Scalar>& H_in, const SparseMatrix<Scalar>& C_in,
                               const SparseMatrix<Scalar>& D_in, const SubspaceOptions& options,
                               VariationalSubspace<Scalar>* out) {
  std::string why;
  if (!options.is_valid(&why)) throw std::invalid_argument("SubspaceOptions: " + why);
  if (out == nullptr) throw std::invalid_argument("build_subspace: output pointer is null");
  const Index n = H_in.rows();
  detail::check_size("build_subspace: H columns (H must be square)", n, H_in.cols());
  detail::check_size("build_subspace: C rows", n, C_in.rows());
  detail::check_size("build_subspace: D rows", n, D_in.rows());
  if (n == 0) throw std::invalid_argument("build_subspace: H is empty");
  if (C_in.cols() == 0) throw std::invalid_argument("build_subspace: C has no columns (d = 0)");
  if (C_in.cols() > n) {
    throw std::invalid_argument(fmt::format("build_subspace: C has more columns ({}) than rows ({})",
                                            C_in.cols(), n));
  }
  detail::check_finite("build_subspace: H", H_in);
  detail::check_finite("build_subspace: C", C_in);
  detail::check_finite("build_subspace: D", D_in);
  detail::check_symmetric("build_subspace: H", H_in, options.symmetry_tolerance);
  for (Index c : options.augment_columns) {
    if (c < 0 || c >= C_in.cols()) {
      throw std::invalid_argument(fmt::format(
          "SubspaceOptions::augment_columns: column {} out of range [0, {})", c, C_in.cols()));
    }
  }

  out->N.resize(0, 0);
  out->UD.resize(0, 0);
  const detail::Timer total;
  SubspaceSummary summary;
  const Index d = C_in.cols(), k = D_in.cols();
  summary.n = n;
  summary.d = d;
  summary.k = k;

  const SpD H = H_in.template cast<double>();
  const SpD C = C_in.template cast<double>();
  const SpD D = D_in.template cast<double>();

  auto fail = [&](Status status, std::string message) {
    summary.status = status;
    summary.message = std::move(message);
    summary.total_seconds = total.seconds();
    return summary;
  };

  // Rank of C, independent of H: CᵀC must be SPD.
  {
    const auto eig = detail::symmetric_eigenvalues(MatD(C.transpose() * C));
    const Index rank = detail::numerical_rank(eig, options.rank_tolerance);
    if (rank < d) {
      return fail(Status::RankDeficientC,
                  fmt::format("C has rank {} < d = {} columns: its columns are linearly dependent", rank, d));
    }
  }

  const Backend spd_backend = options.backend == Backend::SimplicialLDLT ? Backend::SimplicialLDLT
                                                                         : Backend::Cholmod;
  if (options.check_psd) {
    const detail::Timer t;
    const double tau = options.psd_shift * std::max(H.diagonal().cwiseAbs().maxCoeff(), 1e-300);
    SpD shifted = H;
    SpD I(n, n);
    I.setIdentity();
    shifted += tau * I;
    auto check = make_factorization(spd_backend);
    check->compute(shifted);
    summary.check_psd_seconds = t.seconds();
    if (check->info() != Eigen::Success) {
      return fail(Status::IndefiniteH,
                  fmt::format("H is not positive semi-definite: H + {:.2e}·I failed to factor ({})", tau,
                              check->message()));
    }
  }

  // Choose the route: augmented Cholesky, or SparseLU of the KKT matrix.
  std::vector<Index> aug = options.augment_columns;
  if (aug.empty()) {
    aug.resize(d);
    for (Index j = 0; j < d; ++j) aug[j] = j;
  }
  double fill = 0.0, col_norm2 = 0.0;
  for (Index j : aug) {
    const double nz = static_cast<double>(C.col(j).nonZeros());
    fill += nz * nz;
    col_norm2 += C.col(j).squaredNorm();
  }
  const bool kkt_route =
      options.backend == Backend::SparseLU ||
      (options.backend == Backend::Auto && fill > options.max_augmentation_fill * H.nonZeros());

  MatD B;  // [N UD], n × (d + k)
  if (!kkt_route) {
    const double mean_diag = H.diagonal().cwiseAbs().mean();
    summary.rho = options.rho_scale * (mean_diag > 0 ? mean_diag : 1.0) /
                  (col_norm2 / static_cast<double>(aug.size()));
    SpD Cp(n, static_cast<Index>(aug.size()));
    {
      std::vector<Eigen::Triplet<double>> t;
      for (size_t c = 0; c < aug.size(); ++c)
        for (SpD::InnerIterator it(C, aug[c]); it; ++it) t.emplace_back(it.row(), c, it.value());
      Cp.setFromTriplets(t.begin(), t.end());
    }
    const SpD Hrho = SpD(H + summary.rho * (Cp * Cp.transpose())).pruned();

    detail::Timer t;
    auto factor = make_factorization(spd_backend);
    factor->compute(Hrho);
    summary.factorize_seconds = t.seconds();
    summary.backend_used = factor->backend();
    summary.factor_nonzeros = factor->factorNonZeros();
    if (factor->info() != Eigen::Success) {
      return fail(Status::SingularKKT,
                  "H + ρCCᵀ is not positive definite, so the KKT matrix [[H, C], [Cᵀ, 0]] is singular: "
                  "H is not positive definite on ker(Cᵀ) (" + factor->message() + ")");
    }
    summary.probe_error = probe_error(*factor, Hrho);
    if (summary.probe_error > options.max_probe_error) {
      return fail(Status::SingularKKT,
                  fmt::format("H + ρCCᵀ is singular to working precision (a solve with a known answer came back "
                              "with relative error {:.2e}): H is not positive definite on ker(Cᵀ)",
                              summary.probe_error));
    }

    t.reset();
    MatD GF(n, d + k);
    GF.leftCols(d) = MatD(C);
    if (k > 0) GF.rightCols(k) = MatD(D);
    factor->solveInPlace(GF, options.block_size);
    summary.solve_seconds = t.seconds();

    // S = CᵀG is SPD when C has full rank and H_ρ is SPD.
    MatD S = C.transpose() * GF.leftCols(d);
    S = 0.5 * (S + S.transpose()).eval();
    const auto eig = detail::symmetric_eigenvalues(S);
    summary.s_condition = eig.maxCoeff() / std::max(eig.minCoeff(), 1e-300);
    if (detail::numerical_rank(eig, options.rank_tolerance) < d) {
      return fail(Status::SingularKKT,
                  fmt::format("S = Cᵀ(H + ρCCᵀ)⁻¹C is singular (condition {:.2e}): the KKT matrix is "
                              "singular to working precision",
                              summary.s_condition));
    }
    const Eigen::LLT<MatD> Sllt(S);
    B.resize(n, d + k);
    // N = G S⁻¹ = (S⁻¹ Gᵀ)ᵀ since S is symmetric.
    B.leftCols(d) = Sllt.solve(GF.leftCols(d).transpose()).transpose();
    if (k > 0) {
      const MatD W = Sllt.solve(MatD(C.transpose() * GF.rightCols(k)));  // S⁻¹CᵀF, d×k
      B.rightCols(k) = GF.rightCols(k);
      B.rightCols(k).noalias() -= GF.leftCols(d) * W;
    }
  } else {
    detail::Timer t;
    const SpD K = kkt_matrix(H, C);
    auto factor = make_factorization(Backend::SparseLU);
    factor->compute(K);
    summary.factorize_seconds = t.seconds();
    summary.backend_used = Backend::SparseLU;
    summary.factor_nonzeros = factor->factorNonZeros();
    if (factor->info() != Eigen::Success) {
      return fail(Status::SingularKKT,
                  "the KKT matrix [[H, C], [Cᵀ, 0]] is singular: H is not positive definite on ker(Cᵀ) (" +
                      factor->message() + ")");
    }
    summary.probe_error = probe_error(*factor, K);
    if (summary.probe_error > options.max_probe_error) {
      return fail(Status::SingularKKT,
                  fmt::format("the KKT matrix [[H, C], [Cᵀ, 0]] is singular to working precision (a solve with a "
                              "known answer came back with relative error {:.2e}): H is not positive definite on "
                              "ker(Cᵀ)",
                              summary.probe_error));
    }
    t.reset();
    MatD rhs = MatD::Zero(n + d, d + k);
    rhs.bottomLeftCorner(d, d).setIdentity();
    if (k > 0) rhs.topRightCorner(n, k) = MatD(D);
    factor->solveInPlace(rhs, options.block_size);
    summary.solve_seconds = t.seconds();
    if (!rhs.allFinite()) {
      return fail(Status::SingularKKT, "the KKT matrix is singular: SparseLU produced non-finite values");
    }
    B = rhs.topRows(n);
    summary.s_condition = 0.0;
  }

  // U·D must have full column rank: (UD)ᵀH(UD) = Dᵀ·UD is SPD iff no
  // combination of D's columns lies in Span(C).
  if (k > 0 && options.check_dependent_cd) {
    MatD G = D.transpose() * B.rightCols(k);
    G = 0.5 * (G + G.transpose()).eval();
    const auto eig = detail::symmetric_eigenvalues(G);
    const double hn = H.norm();
    const double scale = std::max(eig.cwiseAbs().maxCoeff(), hn > 0 ? D.squaredNorm() / hn : 0.0);
    summary.ud_condition = eig.maxCoeff() / std::max(eig.minCoeff(), 1e-300);
    const Index rank = (eig.array() > options.rank_tolerance * scale).count();
    if (rank < k) {
      return fail(Status::DependentCD,
                  fmt::format("C and D are linearly dependent: U·D has rank {} < k = {} (some combination "
                              "of D's columns lies in Span(C))",
                              rank, k));
    }
  }

  if (!B.allFinite()) return fail(Status::NumericalFailure, "the subspace contains non-finite values");
  if (options.compute_residual) summary.kkt_residual = kkt_residual(H, C, D, B);

  out->N = B.leftCols(d).template cast<Scalar>();
  out->UD = B.rightCols(k).template cast<Scalar>();
  summary.status = Status::Success;
  summary.message = "subspace built";
  summary.total_seconds = total.seconds();
  return summary;
}

template SubspaceSummary build_subspace<double>(const SparseMatrix<double>&, const SparseMatrix<double>&,
                                                const SparseMatrix<double>&, const SubspaceOptions&,
                                                VariationalSubspace<double>*);
template SubspaceSummary build_subspace<float>(const SparseMatrix<float>&, const SparseMatrix<float>&,
                                               const SparseMatrix<float>&, const SubspaceOptions&,
                                               VariationalSubspace<float>*);

}  // namespace qpreduce
