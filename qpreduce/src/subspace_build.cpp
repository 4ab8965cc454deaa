// build_subspace (Eq. 4) as named steps: input checks, the rank of C, the
// route (augmented Cholesky of H_ρ or SparseLU of the KKT matrix), N and UD,
// the rank of U·D, and the extras the reduced solver needs.
#include "qpreduce/subspace.h"

#include "blas.h"
#include "dense.h"
#include "subspace_internal.h"

#include "qpreduce/checks.h"
#include "qpreduce/util/timer.h"
#include "qpreduce/util/heap.h"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <fmt/format.h>

#include <algorithm>
#include <optional>
#include <string>
#include <vector>

namespace qpreduce {
namespace detail {

using SpD = SparseMatrix<double>;
using MatD = Matrix<double>;

namespace {

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

// One subspace build (Eq. 4): the checks, the route (augmented Cholesky of
// H_ρ = H + ρ·CpCpᵀ, or SparseLU of the KKT matrix), N and UD, and the
// optional extras. Each step returns false after recording a failure with
// fail(), which also empties the outputs.
template <typename Scalar>
class SubspaceBuild {
 public:
  SubspaceBuild(const SparseMatrix<Scalar>& H_in, const SparseMatrix<Scalar>& C_in, const SparseMatrix<Scalar>& D_in,
                const SubspaceOptions& options, VariationalSubspace<Scalar>* out)
      : H(as_double(H_in, H_store)),
        C(as_double(C_in, C_store)),
        D(as_double(D_in, D_store)),
        options(options),
        out(out),
        Nw(work.N(out)),
        Uw(work.UD(out)),
        n(H_in.rows()),
        d(C_in.cols()),
        k(D_in.cols()),
        spd_backend(options.backend == Backend::SimplicialLDLT ? Backend::SimplicialLDLT : Backend::Cholmod),
        tau(options.psd_shift * std::max(H.diagonal().cwiseAbs().maxCoeff(), 1e-300)) {
    summary.n = n;
    summary.d = d;
    summary.k = k;
  }

  SubspaceSummary run(SubspaceExtras* extras);

 private:
  bool fail(Status status, std::string message);
  bool fail_kkt(std::string message);
  bool psd_by_factorization();
  bool check_rank_of_C();
  std::vector<Index> augmented_columns() const;
  bool augmented_route(const std::vector<Index>& aug);
  bool kkt_route();
  bool certify_psd(const std::vector<Index>& aug, const MatD& S, double hrho_bound);
  void null_space_and_ud(const MatD& S);
  bool check_ud_rank(const MatD& DtUD);

  const Timer total;
  SpD H_store, C_store, D_store;
  const SpD &H, &C, &D;
  const SubspaceOptions& options;
  VariationalSubspace<Scalar>* out;
  Workspace<Scalar> work;
  MatD& Nw;  // n × d: G, then N
  MatD& Uw;  // n × k: F, then UD
  const Index n, d, k;
  const Backend spd_backend;
  const double tau;  // the shift of the PSD check, H + τI
  std::optional<bool> psd_by_factor_;
  std::string psd_message_;
  SubspaceSummary summary;
};

template <typename Scalar>
bool SubspaceBuild<Scalar>::fail(Status status, std::string message) {
  summary.status = status;
  summary.message = std::move(message);
  summary.total_seconds = total.seconds();
  Nw.resize(0, 0);
  Uw.resize(0, 0);
  out->N.resize(0, 0);
  out->UD.resize(0, 0);
  return false;
}

// Before reporting a numerical failure of H_ρ, say IndefiniteH when that is the cause.
template <typename Scalar>
bool SubspaceBuild<Scalar>::fail_kkt(std::string message) {
  if (options.check_psd && !psd_by_factorization()) return fail(Status::IndefiniteH, psd_message_);
  return fail(Status::SingularKKT, std::move(message));
}

// The PSD check by factorization: LDLᵀ/LLᵀ of H + τI. Returns false (and
// sets psd_message_) when H is not PSD. Runs at most once.
template <typename Scalar>
bool SubspaceBuild<Scalar>::psd_by_factorization() {
  if (psd_by_factor_) return *psd_by_factor_;
  const Timer t;
  SpD shifted = H;
  SpD I(n, n);
  I.setIdentity();
  shifted += tau * I;
  auto check = make_factorization(spd_backend);
  check->setOrderingGroups(options.ordering_groups);
  check->compute(shifted);
  summary.check_psd_seconds += t.seconds();
  psd_by_factor_ = check->info() == Eigen::Success;
  if (!*psd_by_factor_) {
    psd_message_ = fmt::format("H is not positive semi-definite: H + {:.2e}·I failed to factor ({})", tau,
                               check->message());
  }
  return *psd_by_factor_;
}

// Rank of C, independent of H: CᵀC must be SPD.
template <typename Scalar>
bool SubspaceBuild<Scalar>::check_rank_of_C() {
  // (CᵀC is diagonal when no two columns share a row, a selection for one:
  // its eigenvalues are then its diagonal, without a dense d × d solver.)
  const SpD CtC = C.transpose() * C;
  bool diagonal = true;
  for (Index j = 0; j < CtC.outerSize() && diagonal; ++j)
    for (SpD::InnerIterator it(CtC, j); it; ++it) diagonal = diagonal && (it.row() == j || it.value() == 0.0);
  Eigen::VectorXd eig;
  if (diagonal) {
    eig = CtC.diagonal();
    std::sort(eig.data(), eig.data() + eig.size());
  } else {
    eig = detail::symmetric_eigenvalues(MatD(CtC));
  }
  const Index rank = detail::numerical_rank(eig, options.rank_tolerance);
  if (rank < d) {
    return fail(Status::RankDeficientC,
                fmt::format("C has rank {} < d = {} columns: its columns are linearly dependent", rank, d));
  }
  return true;
}

// The columns Cp of C that augment H (all of them by default, none without augmentation).
template <typename Scalar>
std::vector<Index> SubspaceBuild<Scalar>::augmented_columns() const {
  std::vector<Index> aug = options.augment_columns;
  if (!options.augment) {
    aug.clear();  // factor H itself
  } else if (aug.empty()) {
    aug.resize(d);
    for (Index j = 0; j < d; ++j) aug[j] = j;
  }
  return aug;
}

template <typename Scalar>
SubspaceSummary SubspaceBuild<Scalar>::run(SubspaceExtras* extras) {
  if (!check_rank_of_C()) return summary;

  // Choose the route: augmented Cholesky, or SparseLU of the KKT matrix.
  const std::vector<Index> aug = augmented_columns();
  double fill = 0.0;
  for (Index j : aug) {
    const double nz = static_cast<double>(C.col(j).nonZeros());
    fill += nz * nz;
  }
  const bool use_kkt =
      options.backend == Backend::SparseLU ||
      (options.backend == Backend::Auto && fill > options.max_augmentation_fill * H.nonZeros());
  // The factorization check runs first where no certificate will be available.
  const bool psd_first = options.check_psd && (use_kkt || options.psd_check_by_factorization);
  if (psd_first && !psd_by_factorization()) {
    fail(Status::IndefiniteH, psd_message_);
    return summary;
  }
  if (!(use_kkt ? kkt_route() : augmented_route(aug))) return summary;
  snap_selected_rows(C, 0, Nw, Uw);

  // U·D must have full column rank: (UD)ᵀH(UD) = Dᵀ·UD is SPD iff no
  // combination of D's columns lies in Span(C).
  const MatD DtUD = k > 0 ? sparse_transpose_times(D, Uw) : MatD(0, 0);  // k × k
  if (!check_ud_rank(DtUD)) return summary;

  if (!Nw.allFinite() || !Uw.allFinite()) {
    fail(Status::NumericalFailure, "the subspace contains non-finite values");
    return summary;
  }
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

// Augmented route: factor H_ρ = H + ρ·CpCpᵀ (SPD when H is PD on ker Cᵀ),
// solve G = H_ρ⁻¹C and F = H_ρ⁻¹D, then S = CᵀG, N = G·S⁻¹ and
// UD = F − N·CᵀF.
template <typename Scalar>
bool SubspaceBuild<Scalar>::augmented_route(const std::vector<Index>& aug) {
  double col_norm2 = 0.0;
  for (Index j : aug) col_norm2 += C.col(j).squaredNorm();
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
  const Eigen::VectorXd eig = detail::symmetric_eigenvalues(S);
  summary.s_condition = eig.maxCoeff() / std::max(eig.minCoeff(), 1e-300);
  if (detail::numerical_rank(eig, options.rank_tolerance) < d) {
    return fail_kkt(fmt::format("S = Cᵀ(H + ρCCᵀ)⁻¹C is singular (condition {:.2e}): the KKT matrix is "
                                "singular to working precision",
                                summary.s_condition));
  }
  if (!certify_psd(aug, S, hrho_bound)) return false;
  null_space_and_ud(S);
  return true;
}

// PSD certificate. With T = ρ·CpᵀH_ρ⁻¹Cp (the augmenting block of ρS), the
// pencil H − μH_ρ has μ_min = 1 − λ_max(T), so λ_max(T) ≤ 1 + η gives
// H ⪰ −η·H_ρ ⪰ −η·λ_max(H_ρ)·I. With η ≤ τ/λ̄ (λ̄ a Gershgorin bound on
// λ_max(H_ρ)) that certifies H + τI ⪰ 0, which is what the factorization
// check asks. Only when the certificate fails is the factorization run.
// Without augmentation H itself was factored as SPD: nothing to certify.
template <typename Scalar>
bool SubspaceBuild<Scalar>::certify_psd(const std::vector<Index>& aug, const MatD& S, double hrho_bound) {
  if (!(options.check_psd && !options.psd_check_by_factorization && !aug.empty())) return true;
  const Timer tc;
  MatD T(aug.size(), aug.size());
  for (size_t a = 0; a < aug.size(); ++a)
    for (size_t b = 0; b < aug.size(); ++b) T(a, b) = summary.rho * S(aug[a], aug[b]);
  const double lambda_max = detail::symmetric_eigenvalues(T).maxCoeff();
  const double eta_max = tau / std::max(hrho_bound, 1e-300);
  summary.check_psd_seconds += tc.seconds();
  if (!(lambda_max - 1.0 <= eta_max) && !psd_by_factorization()) return fail(Status::IndefiniteH, psd_message_);
  return true;
}

// In place, by row blocks: N = G·S⁻¹, then UD = F − G·S⁻¹·CᵀF = F − N·CᵀF.
template <typename Scalar>
void SubspaceBuild<Scalar>::null_space_and_ud(const MatD& S) {
  // S⁻¹ = L⁻ᵀ·L⁻¹ from S = L·Lᵀ, the two d³ steps through the BLAS.
  const Eigen::LLT<MatD> llt(S);
  MatD Linv = MatD::Identity(d, d);
  blas_lower_solve(llt.matrixLLT(), Linv);
  MatD Sinv(d, d);
  blas_gemm(true, false, 1.0, Linv, Linv, 0.0, Sinv);
  Sinv = 0.5 * (Sinv + Sinv.transpose()).eval();
  const MatD CtF = k > 0 ? MatD(C.transpose() * Uw) : MatD(d, 0);  // d × k
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

// KKT route: SparseLU of [[H, C], [Cᵀ, 0]] and one solve for [N UD]
// (Eq. 4 with right-hand sides [0 D; I 0]).
template <typename Scalar>
bool SubspaceBuild<Scalar>::kkt_route() {
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
  return true;
}

template <typename Scalar>
bool SubspaceBuild<Scalar>::check_ud_rank(const MatD& DtUD) {
  if (!(k > 0 && options.check_dependent_cd)) return true;
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
  return true;
}

// Throws std::invalid_argument on bad sizes, NaN/Inf, asymmetry or invalid options.
template <typename Scalar>
void check_build_inputs(const SparseMatrix<Scalar>& H, const SparseMatrix<Scalar>& C, const SparseMatrix<Scalar>& D,
                        const SubspaceOptions& options, const VariationalSubspace<Scalar>* out) {
  std::string why;
  if (!options.is_valid(&why)) throw std::invalid_argument("SubspaceOptions: " + why);
  if (out == nullptr) throw std::invalid_argument("build_subspace: output pointer is null");
  const Index n = H.rows();
  check_size("build_subspace: H columns (H must be square)", n, H.cols());
  check_size("build_subspace: C rows", n, C.rows());
  check_size("build_subspace: D rows", n, D.rows());
  if (n == 0) throw std::invalid_argument("build_subspace: H is empty");
  if (C.cols() == 0) throw std::invalid_argument("build_subspace: C has no columns (d = 0)");
  if (C.cols() > n) {
    throw std::invalid_argument(fmt::format("build_subspace: C has more columns ({}) than rows ({})", C.cols(), n));
  }
  check_finite("build_subspace: H", H);
  check_finite("build_subspace: C", C);
  check_finite("build_subspace: D", D);
  check_symmetric("build_subspace: H", H, options.symmetry_tolerance);
  if (!options.ordering_groups.empty()) {
    check_size("SubspaceOptions::ordering_groups size (one group per unknown)", n,
               static_cast<Index>(options.ordering_groups.size()));
    for (Index g : options.ordering_groups) {
      if (g < 0) throw std::invalid_argument(fmt::format("SubspaceOptions::ordering_groups: negative group {}", g));
    }
  }
  for (Index c : options.augment_columns) {
    if (c < 0 || c >= C.cols()) {
      throw std::invalid_argument(
          fmt::format("SubspaceOptions::augment_columns: column {} out of range [0, {})", c, C.cols()));
    }
  }
}

}  // namespace

template <typename Scalar>
SubspaceSummary build_subspace_with_extras(const SparseMatrix<Scalar>& H, const SparseMatrix<Scalar>& C,
                                           const SparseMatrix<Scalar>& D, const SubspaceOptions& options,
                                           VariationalSubspace<Scalar>* out, SubspaceExtras* extras) {
  check_build_inputs(H, C, D, options, out);
  out->N.resize(0, 0);
  out->UD.resize(0, 0);
  if (extras) *extras = SubspaceExtras{};
  return SubspaceBuild<Scalar>(H, C, D, options, out).run(extras);
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
