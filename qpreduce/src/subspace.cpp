#include "qpreduce/subspace.h"

#include "blas.h"
#include "simd_kernels.h"
#include "subspace_internal.h"

#include "dense.h"
#include "qpreduce/support.h"

#include <Eigen/Eigenvalues>
#include <fmt/format.h>

#include <omp.h>

#include <algorithm>
#include <cassert>
#include <cmath>
#include <optional>
#include <vector>

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
  if (!(reduced_lift_tolerance >= 0.0 && reduced_lift_tolerance < 1.0)) {
    return fail("reduced_lift_tolerance must lie in [0, 1)");
  }
  return true;
}

std::string SubspaceSummary::brief_report() const {
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

// Rows per block for the row-blocked dense passes (N = G·S⁻¹, Dᵀ·X): a
// 512 × 300 double block is 1.2 MB, a few L2-sized panels for the GEMM kernel.
constexpr Index kRowBlock = 512;
// Columns per block of the blocked residual / BᵀHB pass.
constexpr Index kResidualColumns = 32;

// One pass over column blocks B_j of B = [N UD] (OpenMP over blocks, so no
// n × p temporary), each with one sparse product H·B_j, computing
//   * `residual` (when not null): the relative residual of Eq. 4, see
//     SubspaceSummary::kkt_residual — H·B_j, projected off Span(C);
//   * `gram` (when not null): H_r = BᵀHB (p × p), the blocks on and above the
//     diagonal as B(:, :j_end)ᵀ·(H·B_j), mirrored below.
void blocked_pass(const SpD& H, const SpD& C, const SpD& D, const MatD& N, const MatD& UD, double* residual,
                  MatD* gram) {
  const Index d = N.cols(), k = UD.cols(), p = d + k;
  const Eigen::LDLT<MatD> CtC(MatD(C.transpose() * C));
  const Index nb_d = (d + kResidualColumns - 1) / kResidualColumns;
  const Index nb_k = (k + kResidualColumns - 1) / kResidualColumns;
  if (gram) gram->setZero(p, p);
  const detail::ScopedBlasThreads one_blas_thread(1);  // the OpenMP loop below calls the BLAS from each thread
  // H by rows (a copy, so that H need not be exactly symmetric) for the
  // row-major panel product of detail::sparse_times_block.
  const Eigen::SparseMatrix<double, Eigen::RowMajor, int> Hrows = H;
  double r1sq = 0.0, r2sq = 0.0;
  // Later blocks have taller Gram panels: hand them out first.
#pragma omp parallel reduction(+ : r1sq, r2sq)
  {
    MatD HBbuf(H.rows(), kResidualColumns);  // reused: fresh n-sized buffers cost page faults
    std::vector<double> panel(static_cast<size_t>(H.cols() * kResidualColumns));
#pragma omp for schedule(dynamic, 1)
    for (Index bb = 0; bb < nb_d + nb_k; ++bb) {
      const Index b = nb_d + nb_k - 1 - bb;
      const bool in_n = b < nb_d;
      const Index j = (in_n ? b : b - nb_d) * kResidualColumns;
      const Index w = std::min(kResidualColumns, (in_n ? d : k) - j);
      const Index col = in_n ? j : d + j;  // first column of the block in B
      const auto Bj = in_n ? N.middleCols(j, w) : UD.middleCols(j, w);
      auto HB = HBbuf.leftCols(w);
      detail::sparse_times_block(Hrows, Bj.data(), Bj.outerStride(), w, panel.data(), HB.data(), HB.outerStride());
      if (gram) {
        const Index end = col + w, rows_n = std::min(d, end), rows_u = std::max<Index>(0, end - d);
        detail::blas_gemm(true, false, 1.0, N.leftCols(rows_n), HB, 0.0, gram->block(0, col, rows_n, w));
        if (rows_u > 0) detail::blas_gemm(true, false, 1.0, UD.leftCols(rows_u), HB, 0.0, gram->block(d, col, rows_u, w));
      }
      if (residual) {
        if (!in_n) HB -= D.middleCols(j, w);
        const MatD coef = CtC.solve(MatD(C.transpose() * HB));
        HB.noalias() -= C * coef;
        r1sq += HB.squaredNorm();
        MatD R2 = C.transpose() * Bj;
        if (in_n) R2.middleRows(j, w) -= MatD::Identity(w, w);
        r2sq += R2.squaredNorm();
      }
    }
  }
  if (gram) {
    const MatD upper = *gram;
    gram->triangularView<Eigen::StrictlyLower>() = upper.transpose();
  }
  if (residual) {
    const double bnorm = std::sqrt(N.squaredNorm() + UD.squaredNorm());
    // (Eigen asserts on the norm of a matrix with no columns: k = 0 is valid.)
    const double scale1 = H.norm() * bnorm + (D.cols() > 0 ? D.norm() : 0.0);
    const double scale2 = C.norm() * bnorm;
    const double r1 = scale1 > 0 ? std::sqrt(r1sq) / scale1 : std::sqrt(r1sq);
    const double r2 = scale2 > 0 ? std::sqrt(r2sq) / scale2 : std::sqrt(r2sq);
    *residual = std::max(r1, r2);
  }
}

// S as a dense matrix whose every page is written first, by the OpenMP
// threads. MatD(S) lets the compiler turn the allocation and the zero fill
// into one calloc, whose fresh pages the solve then reads before writing:
// each page is first mapped to the shared zero page, and the write that
// follows copies it and flushes the other threads' TLBs (an interrupt per
// page; about 1 s of CPU on 121k × 342 right-hand sides).
MatD dense_written(const SpD& S) {
  MatD out(S.rows(), S.cols());
#pragma omp parallel for schedule(static)
  for (Index j = 0; j < S.cols(); ++j) {
    out.col(j).setZero();
    for (SpD::InnerIterator it(S, j); it; ++it) out(it.row(), j) = it.value();
  }
  return out;
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

// Gershgorin bound on λ_max of a symmetric sparse matrix: max column sum of |a_ij|.
double gershgorin_bound(const SpD& A) {
  double top = 0.0;
  for (Index j = 0; j < A.outerSize(); ++j) {
    double sum = 0.0;
    for (SpD::InnerIterator it(A, j); it; ++it) sum += std::abs(it.value());
    top = std::max(top, sum);
  }
  return top;
}

// The working matrices of a build are the outputs themselves when Scalar is
// double, and double scratch that is cast at the end otherwise.
template <typename Scalar>
struct Workspace {
  MatD G, F;
  MatD& N(VariationalSubspace<Scalar>*) { return G; }
  MatD& UD(VariationalSubspace<Scalar>*) { return F; }
  void finish(VariationalSubspace<Scalar>* out) {
    out->N = G.template cast<Scalar>();
    G.resize(0, 0);
    out->UD = F.template cast<Scalar>();
    F.resize(0, 0);
  }
};
template <>
struct Workspace<double> {
  MatD& N(VariationalSubspace<double>* out) { return out->N; }
  MatD& UD(VariationalSubspace<double>* out) { return out->UD; }
  void finish(VariationalSubspace<double>*) {}
};

const SpD& as_double(const SparseMatrix<double>& m, SpD&) { return m; }
const SpD& as_double(const SparseMatrix<float>& m, SpD& storage) {
  storage = m.cast<double>();
  return storage;
}

}  // namespace

namespace detail {

ScopedOmpThreads::ScopedOmpThreads(int threads) : previous_(omp_get_max_threads()) {
  if (threads > 0) omp_set_num_threads(threads);
}
ScopedOmpThreads::~ScopedOmpThreads() { omp_set_num_threads(previous_); }

MatD sparse_transpose_times(const SpD& S, const MatD& X) {
  const Index n = S.rows(), a = S.cols(), b = X.cols();
  assert(X.rows() == n);
  const double density = n > 0 && a > 0 ? static_cast<double>(S.nonZeros()) / (static_cast<double>(n) * a) : 0.0;
  // Below this density Eigen's sparse product (nnz·b) beats densifying.
  constexpr double kDenseFrom = 0.05;
  if (density < kDenseFrom || !S.isCompressed()) return MatD(S.transpose() * X);
  const Index blocks = (n + kRowBlock - 1) / kRowBlock;
  MatD result = MatD::Zero(a, b);
  const ScopedBlasThreads one_blas_thread(1);
#pragma omp parallel
  {
    MatD partial = MatD::Zero(a, b), dense(kRowBlock, a);
#pragma omp for schedule(static)
    for (Index blk = 0; blk < blocks; ++blk) {
      const Index r0 = blk * kRowBlock, len = std::min(kRowBlock, n - r0);
      dense.setZero();
      for (Index j = 0; j < a; ++j) {
        const int* rows = S.innerIndexPtr();
        const Index begin = S.outerIndexPtr()[j], end = S.outerIndexPtr()[j + 1];
        const int* first = std::lower_bound(rows + begin, rows + end, static_cast<int>(r0));
        for (Index t = first - rows; t < end && rows[t] < r0 + len; ++t) dense(rows[t] - r0, j) = S.valuePtr()[t];
      }
      blas_gemm(true, false, 1.0, dense.topRows(len), X.middleRows(r0, len), 1.0, partial);
    }
#pragma omp critical
    result += partial;
  }
  return result;
}

template <typename Scalar>
SubspaceSummary build_subspace_with_extras(const SparseMatrix<Scalar>& H_in, const SparseMatrix<Scalar>& C_in,
                                           const SparseMatrix<Scalar>& D_in, const SubspaceOptions& options,
                                           VariationalSubspace<Scalar>* out, SubspaceExtras* extras) {
  std::string why;
  if (!options.is_valid(&why)) throw std::invalid_argument("SubspaceOptions: " + why);
  if (out == nullptr) throw std::invalid_argument("build_subspace: output pointer is null");
  const Index n = H_in.rows();
  check_size("build_subspace: H columns (H must be square)", n, H_in.cols());
  check_size("build_subspace: C rows", n, C_in.rows());
  check_size("build_subspace: D rows", n, D_in.rows());
  if (n == 0) throw std::invalid_argument("build_subspace: H is empty");
  if (C_in.cols() == 0) throw std::invalid_argument("build_subspace: C has no columns (d = 0)");
  if (C_in.cols() > n) {
    throw std::invalid_argument(fmt::format("build_subspace: C has more columns ({}) than rows ({})",
                                            C_in.cols(), n));
  }
  check_finite("build_subspace: H", H_in);
  check_finite("build_subspace: C", C_in);
  check_finite("build_subspace: D", D_in);
  check_symmetric("build_subspace: H", H_in, options.symmetry_tolerance);
  if (!options.ordering_groups.empty()) {
    check_size("SubspaceOptions::ordering_groups size (one group per unknown)", n,
                       static_cast<Index>(options.ordering_groups.size()));
    for (Index g : options.ordering_groups) {
      if (g < 0) throw std::invalid_argument(fmt::format("SubspaceOptions::ordering_groups: negative group {}", g));
    }
  }
  for (Index c : options.augment_columns) {
    if (c < 0 || c >= C_in.cols()) {
      throw std::invalid_argument(fmt::format(
          "SubspaceOptions::augment_columns: column {} out of range [0, {})", c, C_in.cols()));
    }
  }

  out->N.resize(0, 0);
  out->UD.resize(0, 0);
  if (extras) *extras = SubspaceExtras{};
  const Timer total;
  SubspaceSummary summary;
  const Index d = C_in.cols(), k = D_in.cols();
  summary.n = n;
  summary.d = d;
  summary.k = k;

  SpD H_store, C_store, D_store;
  const SpD& H = as_double(H_in, H_store);
  const SpD& C = as_double(C_in, C_store);
  const SpD& D = as_double(D_in, D_store);

  Workspace<Scalar> work;
  MatD& Nw = work.N(out);  // n × d: G, then N
  MatD& Uw = work.UD(out);  // n × k: F, then UD
  auto fail = [&](Status status, std::string message) {
    summary.status = status;
    summary.message = std::move(message);
    summary.total_seconds = total.seconds();
    Nw.resize(0, 0);
    Uw.resize(0, 0);
    out->N.resize(0, 0);
    out->UD.resize(0, 0);
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
  // The PSD check by factorization: LDLᵀ/LLᵀ of H + τI. Returns false (and
  // sets `psd_message`) when H is not PSD. Runs at most once.
  const double tau = options.psd_shift * std::max(H.diagonal().cwiseAbs().maxCoeff(), 1e-300);
  std::optional<bool> psd_by_factor;
  std::string psd_message;
  auto factor_psd_check = [&]() {
    if (psd_by_factor) return *psd_by_factor;
    const Timer t;
    SpD shifted = H;
    SpD I(n, n);
    I.setIdentity();
    shifted += tau * I;
    auto check = make_factorization(spd_backend);
    check->setOrderingGroups(options.ordering_groups);
    check->compute(shifted);
    summary.check_psd_seconds += t.seconds();
    psd_by_factor = check->info() == Eigen::Success;
    if (!*psd_by_factor) {
      psd_message = fmt::format("H is not positive semi-definite: H + {:.2e}·I failed to factor ({})", tau,
                                check->message());
    }
    return *psd_by_factor;
  };
  // Before reporting a numerical failure of H_ρ, say IndefiniteH when that is the cause.
  auto fail_kkt = [&](std::string message) {
    if (options.check_psd && !factor_psd_check()) return fail(Status::IndefiniteH, psd_message);
    return fail(Status::SingularKKT, std::move(message));
  };

  // Choose the route: augmented Cholesky, or SparseLU of the KKT matrix.
  std::vector<Index> aug = options.augment_columns;
  if (!options.augment) {
    aug.clear();  // factor H itself
  } else if (aug.empty()) {
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
  // The factorization check runs first where no certificate will be available.
  const bool psd_first = options.check_psd && (kkt_route || options.psd_check_by_factorization);
  if (psd_first && !factor_psd_check()) return fail(Status::IndefiniteH, psd_message);

  if (!kkt_route) {
    const double mean_diag = H.diagonal().cwiseAbs().mean();
    summary.rho = aug.empty() ? 0.0
                              : options.rho_scale * (mean_diag > 0 ? mean_diag : 1.0) /
                                    (col_norm2 / static_cast<double>(aug.size()));
    SpD Cp(n, static_cast<Index>(aug.size()));
    {
      std::vector<Eigen::Triplet<double>> t;
      for (size_t c = 0; c < aug.size(); ++c)
        for (SpD::InnerIterator it(C, aug[c]); it; ++it) t.emplace_back(it.row(), c, it.value());
      Cp.setFromTriplets(t.begin(), t.end());
    }
    SpD Hrho = SpD(H + summary.rho * (Cp * Cp.transpose())).pruned();

    Timer t;
    auto factor = make_factorization(spd_backend);
    factor->setOrderingGroups(options.ordering_groups);
    factor->compute(Hrho);
    summary.factorize_seconds = t.seconds();
    summary.backend_used = factor->backend();
    summary.factor_nonzeros = factor->factorNonZeros();
    if (factor->info() != Eigen::Success) {
      return fail_kkt("H + ρCCᵀ is not positive definite, so the KKT matrix [[H, C], [Cᵀ, 0]] is singular: "
                      "H is not positive definite on ker(Cᵀ) (" + factor->message() + ")");
    }
    summary.probe_error = probe_error(*factor, Hrho);
    if (summary.probe_error > options.max_probe_error) {
      return fail_kkt(fmt::format("H + ρCCᵀ is singular to working precision (a solve with a known answer came "
                                  "back with relative error {:.2e}): H is not positive definite on ker(Cᵀ)",
                                  summary.probe_error));
    }
    // H_ρ itself is needed no further than its Gershgorin bound (for the PSD
    // certificate below): free it before the solves, where the factor and
    // the n × p solution make the build's memory peak.
    const double hrho_bound = gershgorin_bound(Hrho);
    Hrho = SpD();
    release_free_heap();  // and the analysis's workspace (METIS graphs)

    // G = H_ρ⁻¹C and F = H_ρ⁻¹D, solved in place in the output storage.
    t.reset();
    Nw = dense_written(C);
    factor->solveInPlace(Nw, options.block_size);
    if (k > 0) {
      Uw = dense_written(D);
      factor->solveInPlace(Uw, options.block_size);
    } else {
      Uw.resize(n, 0);
    }
    summary.solve_seconds = t.seconds();
    factor.reset();

    // S = CᵀG is SPD when C has full rank and H_ρ is SPD.
    MatD S = C.transpose() * Nw;
    S = 0.5 * (S + S.transpose()).eval();
    const Eigen::SelfAdjointEigenSolver<MatD> Seig(S, Eigen::EigenvaluesOnly);
    const auto& eig = Seig.eigenvalues();
    summary.s_condition = eig.maxCoeff() / std::max(eig.minCoeff(), 1e-300);
    if (detail::numerical_rank(eig, options.rank_tolerance) < d) {
      return fail_kkt(fmt::format("S = Cᵀ(H + ρCCᵀ)⁻¹C is singular (condition {:.2e}): the KKT matrix is "
                                  "singular to working precision",
                                  summary.s_condition));
    }

    // PSD certificate. With T = ρ·CpᵀH_ρ⁻¹Cp (the augmenting block of ρS),
    // the pencil H − μH_ρ has μ_min = 1 − λ_max(T), so λ_max(T) ≤ 1 + η gives
    // H ⪰ −η·H_ρ ⪰ −η·λ_max(H_ρ)·I. With η ≤ τ/λ̄ (λ̄ a Gershgorin bound on
    // λ_max(H_ρ)) that certifies H + τI ⪰ 0, which is what the factorization
    // check asks. Only when the certificate fails is the factorization run.
    // Without augmentation H itself was factored as SPD: nothing to certify.
    if (options.check_psd && !options.psd_check_by_factorization && !aug.empty()) {
      const Timer tc;
      MatD T(aug.size(), aug.size());
      for (size_t a = 0; a < aug.size(); ++a)
        for (size_t b = 0; b < aug.size(); ++b) T(a, b) = summary.rho * S(aug[a], aug[b]);
      const double lambda_max = detail::symmetric_eigenvalues(T).maxCoeff();
      const double eta_max = tau / std::max(hrho_bound, 1e-300);
      summary.check_psd_seconds += tc.seconds();
      if (!(lambda_max - 1.0 <= eta_max) && !factor_psd_check()) return fail(Status::IndefiniteH, psd_message);
    }

    MatD Sinv = Eigen::LLT<MatD>(S).solve(MatD::Identity(d, d));
    Sinv = 0.5 * (Sinv + Sinv.transpose()).eval();
    const MatD CtF = k > 0 ? MatD(C.transpose() * Uw) : MatD(d, 0);  // d × k
    // In place, by row blocks: N = G·S⁻¹, then UD = F − G·S⁻¹·CᵀF = F − N·CᵀF.
    {
      const Index blocks = (n + kRowBlock - 1) / kRowBlock;
      const ScopedBlasThreads one_blas_thread(1);
#pragma omp parallel
      {
        MatD tmp(kRowBlock, d);
#pragma omp for schedule(static)
        for (Index b = 0; b < blocks; ++b) {
          const Index r = b * kRowBlock, len = std::min(kRowBlock, n - r);
          blas_gemm(false, false, 1.0, Nw.middleRows(r, len), Sinv, 0.0, tmp.topRows(len));
          Nw.middleRows(r, len) = tmp.topRows(len);
          if (k > 0) blas_gemm(false, false, -1.0, tmp.topRows(len), CtF, 1.0, Uw.middleRows(r, len));
        }
      }
    }
  } else {
    Timer t;
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
    Nw = rhs.topLeftCorner(n, d);
    Uw = rhs.topRightCorner(n, k);
    summary.s_condition = 0.0;
  }

  // U·D must have full column rank: (UD)ᵀH(UD) = Dᵀ·UD is SPD iff no
  // combination of D's columns lies in Span(C).
  MatD DtUD = k > 0 ? sparse_transpose_times(D, Uw) : MatD(0, 0);  // k × k
  if (k > 0 && options.check_dependent_cd) {
    MatD G = 0.5 * (DtUD + DtUD.transpose());
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

  if (!Nw.allFinite() || !Uw.allFinite()) return fail(Status::NumericalFailure, "the subspace contains non-finite values");
  if (options.compute_residual || extras) {
    blocked_pass(H, C, D, Nw, Uw, options.compute_residual ? &summary.kkt_residual : nullptr,
                 extras ? &extras->Hr : nullptr);
  }

  if (extras) {
    extras->BtD.resize(d + k, k);
    if (k > 0) {
      extras->BtD.topRows(d) = sparse_transpose_times(D, Nw).transpose();
      extras->BtD.bottomRows(k) = DtUD.transpose();
    }
  }
  work.finish(out);
  summary.status = Status::Success;
  summary.message = "subspace built";
  summary.total_seconds = total.seconds();
  return summary;
}

template SubspaceSummary build_subspace_with_extras<double>(const SparseMatrix<double>&, const SparseMatrix<double>&,
                                                            const SparseMatrix<double>&, const SubspaceOptions&,
                                                            VariationalSubspace<double>*, SubspaceExtras*);
template SubspaceSummary build_subspace_with_extras<float>(const SparseMatrix<float>&, const SparseMatrix<float>&,
                                                           const SparseMatrix<float>&, const SubspaceOptions&,
                                                           VariationalSubspace<float>*, SubspaceExtras*);

}  // namespace detail

template <typename Scalar>
SubspaceSummary build_subspace(const SparseMatrix<Scalar>& H, const SparseMatrix<Scalar>& C,
                               const SparseMatrix<Scalar>& D, const SubspaceOptions& options,
                               VariationalSubspace<Scalar>* out) {
  return detail::build_subspace_with_extras(H, C, D, options, out, nullptr);
}

template SubspaceSummary build_subspace<double>(const SparseMatrix<double>&, const SparseMatrix<double>&,
                                                const SparseMatrix<double>&, const SubspaceOptions&,
                                                VariationalSubspace<double>*);
template SubspaceSummary build_subspace<float>(const SparseMatrix<float>&, const SparseMatrix<float>&,
                                               const SparseMatrix<float>&, const SubspaceOptions&,
                                               VariationalSubspace<float>*);

}  // namespace qpreduce
