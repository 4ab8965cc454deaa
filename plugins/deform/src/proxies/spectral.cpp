// Generalized Laplace–Beltrami eigenpairs L φ = λ M φ (Spectra shift-invert
// Lanczos, or a dense solver for small components) and the per-component
// spectral embedding; see spectral.h and docs/proxies.md.
#include "qpreduce/deform/proxies/spectral.h"

#include "proxies_internal.h"

#include <qpreduce/checks.h>
#include <qpreduce/util/timer.h>

#include <Eigen/Dense>
#include <Eigen/SparseCholesky>
#include <Spectra/SymGEigsShiftSolver.h>

#include <fmt/format.h>

#include <algorithm>
#include <cstdint>
#include <cmath>
#include <limits>
#include <memory>
#include <numeric>
#include <stdexcept>

namespace qpreduce::deform {

namespace {

// (L − σM)⁻¹, optionally followed by the M-orthogonal projection that
// deflates already-found eigenvectors Q (n × f, M-orthonormal):
//     y = P (L − σM)⁻¹ x,   P = I − Q Qᵀ M.
// With T = (L − σM)⁻¹M, Spectra's shift-invert operator is y = P T x; since Q
// spans an invariant subspace of T, P T is still M-self-adjoint, with the found
// eigenvalues moved to 0. Factored once, at construction; Spectra's
// set_shift(σ) must pass the same σ.
class ShiftInvertOp {
 public:
  using Scalar = double;

  ShiftInvertOp(const SparseMatrix<double>& L, const Eigen::VectorXd& mass, double sigma, Backend backend)
      : n_(L.rows()), sigma_(sigma), mass_(mass), buffer_(L.rows(), 1) {
    SparseMatrix<double> A = L;
    for (Index i = 0; i < n_; ++i) A.coeffRef(i, i) -= sigma * mass[i];
    if (backend == Backend::SimplicialLDLT) {
      // Eigen directly: the engine's backend solves column blocks under OpenMP,
      // which costs more than the solve itself for one vector.
      ldlt_.compute(A);
      ok_ = ldlt_.info() == Eigen::Success && (ldlt_.vectorD().array() > 0.0).all();
      message_ = ok_ ? "" : "SimplicialLDLT: L − σM is not positive definite";
    } else {
      factor_ = make_factorization(backend);
      factor_->compute(A);
      ok_ = factor_->info() == Eigen::Success;
      message_ = factor_->message();
    }
  }

  Index rows() const { return n_; }
  Index cols() const { return n_; }
  void set_shift(const double& sigma) {
    if (sigma != sigma_) {
      throw std::logic_error(fmt::format("ShiftInvertOp: factored for the shift {}, asked for {}", sigma_, sigma));
    }
  }
  void deflate(const Matrix<double>* Q) { Q_ = Q; }

  void perform_op(const double* x_in, double* y_out) const {
    const Eigen::Map<const Eigen::VectorXd> x(x_in, n_);
    Eigen::Map<Eigen::VectorXd> y(y_out, n_);
    if (factor_) {
      buffer_.col(0) = x;
      factor_->solveInPlace(buffer_, 1);
      y = buffer_.col(0);
    } else {
      y = ldlt_.solve(x);
    }
    if (Q_ && Q_->cols() > 0) y -= *Q_ * (Q_->transpose() * mass_.cwiseProduct(y));
  }

  bool ok() const { return ok_; }
  const std::string& message() const { return message_; }

 private:
  Index n_;
  double sigma_;
  const Eigen::VectorXd& mass_;
  std::unique_ptr<SparseFactorization> factor_;
  Eigen::SimplicialLDLT<SparseMatrix<double>, Eigen::Lower, Eigen::AMDOrdering<int>> ldlt_;
  mutable Matrix<double> buffer_;  // n × 1, reused by every product
  const Matrix<double>* Q_ = nullptr;
  bool ok_ = false;
  std::string message_;
};

// Number of eigenvalues of L φ = λ M φ below τ: the negative pivots of
// LDLᵀ(L − τM) (Sylvester's law of inertia). −1 when the factorization hits a
// zero pivot.
Index count_below(const SparseMatrix<double>& L, const Eigen::VectorXd& mass, double tau) {
  SparseMatrix<double> A = L;
  for (Index i = 0; i < A.rows(); ++i) A.coeffRef(i, i) -= tau * mass[i];
  Eigen::SimplicialLDLT<SparseMatrix<double>, Eigen::Lower, Eigen::AMDOrdering<int>> ldlt(A);
  if (ldlt.info() != Eigen::Success) return -1;
  const Eigen::VectorXd d = ldlt.vectorD();
  if ((d.array() == 0.0).any()) return -1;
  return (d.array() < 0.0).count();
}

// Deterministic start vector for Lanczos (Spectra's own is fixed too, but it
// cannot be projected against deflated vectors).
Eigen::VectorXd start_vector(Index n, std::uint64_t seed) {
  std::uint64_t state = seed;
  Eigen::VectorXd v(n);
  for (Index i = 0; i < n; ++i) {
    state = state * 6364136223846793005ull + 1442695040888963407ull;  // PCG/Knuth LCG step
    v[i] = static_cast<double>(state >> 11) * 0x1.0p-53 - 0.5;
  }
  return v;
}

// y = M x for the diagonal mass matrix (Spectra's B operator).
class DiagonalOp {
 public:
  using Scalar = double;
  explicit DiagonalOp(const Eigen::VectorXd& mass) : mass_(mass) {}
  Index rows() const { return mass_.size(); }
  Index cols() const { return mass_.size(); }
  void perform_op(const double* x_in, double* y_out) const {
    Eigen::Map<Eigen::VectorXd>(y_out, rows()) =
        mass_.cwiseProduct(Eigen::Map<const Eigen::VectorXd>(x_in, rows()));
  }

 private:
  const Eigen::VectorXd& mass_;
};

double max_abs_row_sum(const SparseMatrix<double>& A) {
  Eigen::VectorXd sums = Eigen::VectorXd::Zero(A.rows());
  for (Index j = 0; j < A.outerSize(); ++j) {
    for (SparseMatrix<double>::InnerIterator it(A, j); it; ++it) sums[it.row()] += std::abs(it.value());
  }
  return A.rows() > 0 ? sums.maxCoeff() : 0.0;
}

// Sorts ascending, M-normalises, and measures the relative residuals.
double finish_pairs(const SparseMatrix<double>& L, const Eigen::VectorXd& mass, Eigenpairs* pairs) {
  const Index count = pairs->values.size();
  std::vector<Index> order(static_cast<std::size_t>(count));
  std::iota(order.begin(), order.end(), 0);
  std::sort(order.begin(), order.end(), [&](Index a, Index b) { return pairs->values[a] < pairs->values[b]; });
  Eigenpairs sorted;
  sorted.values.resize(count);
  sorted.vectors.resize(L.rows(), count);
  for (Index j = 0; j < count; ++j) {
    sorted.values[j] = pairs->values[order[j]];
    const Eigen::VectorXd& phi = pairs->vectors.col(order[j]);
    sorted.vectors.col(j) = phi / std::sqrt(phi.dot(mass.cwiseProduct(phi)));
  }
  *pairs = std::move(sorted);
  const double norm_L = max_abs_row_sum(L), norm_M = mass.cwiseAbs().maxCoeff();
  double worst = 0.0;
  for (Index j = 0; j < count; ++j) {
    const Eigen::VectorXd phi = pairs->vectors.col(j);
    const double lambda = pairs->values[j];
    const double r = (L * phi - lambda * mass.cwiseProduct(phi)).norm();
    const double scale = (norm_L + std::abs(lambda) * norm_M) * phi.norm();
    worst = std::max(worst, scale > 0.0 ? r / scale : r);
  }
  return worst;
}

void dense_pairs(const SparseMatrix<double>& L, const Eigen::VectorXd& mass, Index count, Eigenpairs* out) {
  // M^{-1/2} L M^{-1/2} ψ = λ ψ,  φ = M^{-1/2} ψ.
  const Eigen::VectorXd s = mass.cwiseSqrt().cwiseInverse();
  const Eigen::MatrixXd A = s.asDiagonal() * Eigen::MatrixXd(L) * s.asDiagonal();
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(A);
  out->values = eig.eigenvalues().head(count);
  out->vectors = s.asDiagonal() * eig.eigenvectors().leftCols(count);
}

// Bounding-box diagonal of a subset of V's rows.
double subset_diagonal(const VerticesRef& V, const std::vector<Index>& rows) {
  Eigen::RowVector3d lo = V.row(rows.front()), hi = lo;
  for (Index v : rows) {
    lo = lo.cwiseMin(V.row(v));
    hi = hi.cwiseMax(V.row(v));
  }
  return (hi - lo).norm();
}

}  // namespace

bool SpectralOptions::is_valid(std::string* why) const {
  const auto fail = [why](const char* reason) { return detail::reject(why, reason); };
  if (eigenvectors < 1) return fail("SpectralOptions: eigenvectors must be ≥ 1");
  if (!(shift_scale > 0.0) || !std::isfinite(shift_scale)) return fail("SpectralOptions: shift_scale must be > 0");
  if (backend == Backend::SparseLU) return fail("SpectralOptions: backend must be symmetric (Cholmod or SimplicialLDLT)");
  if (min_lanczos_vectors < 2) return fail("SpectralOptions: min_lanczos_vectors must be ≥ 2");
  if (max_restarts < 1) return fail("SpectralOptions: max_restarts must be ≥ 1");
  if (!(tolerance > 0.0)) return fail("SpectralOptions: tolerance must be > 0");
  if (!(zero_tolerance >= 0.0)) return fail("SpectralOptions: zero_tolerance must be ≥ 0");
  if (dense_max_size < 0) return fail("SpectralOptions: dense_max_size must be ≥ 0");
  if (!(inertia_margin > 0.0)) return fail("SpectralOptions: inertia_margin must be > 0");
  if (max_deflation_rounds < 0) return fail("SpectralOptions: max_deflation_rounds must be ≥ 0");
  return true;
}

std::string SpectralSummary::brief_report() const {
  return fmt::format("spectral: {}{}{} | {} components, {} eigenpairs, {} Lanczos products, {} deflation rounds, "
                     "residual {:.2e} | "
                     "factorize {:.3f}s, eigen {:.3f}s, total {:.3f}s",
                     to_string(status), message.empty() ? "" : " — ", message, components, eigenpairs,
                     lanczos_operations, deflation_rounds, max_relative_residual, factorize_seconds, eigen_seconds, total_seconds);
}

namespace {

bool fail(SpectralSummary* summary, std::string message) {
  summary->status = Status::NumericalFailure;
  summary->message = std::move(message);
  return false;
}

// Eigenpairs found so far by the Lanczos rounds: Q (n × f, M-orthonormal) and
// their eigenvalues, in the order found.
struct FoundPairs {
  Matrix<double> Q;
  std::vector<double> values;
};

// One round of shift-invert Lanczos (Spectra) for `need` more eigenpairs of
// the operator with found->Q deflated; the new vectors are re-orthogonalised
// against earlier rounds (M inner product), normalised and appended.
bool lanczos_round(ShiftInvertOp& op, DiagonalOp& mop, const Eigen::VectorXd& mass, Index need, double sigma,
                   Index round, const SpectralOptions& options, FoundPairs* found, SpectralSummary* summary) {
  const Index n = mass.size();
  Matrix<double>& Q = found->Q;
  const Index ncv = std::min(n - Q.cols(), std::max(2 * need + 1, options.min_lanczos_vectors));
  if (ncv <= need) {
    return fail(summary, fmt::format("too few vectors left for Lanczos: {} eigenpairs wanted, n = {}, {} deflated",
                                     need, n, Q.cols()));
  }
  op.deflate(&Q);
  Spectra::SymGEigsShiftSolver<ShiftInvertOp, DiagonalOp, Spectra::GEigsMode::ShiftInvert> solver(op, mop, need,
                                                                                                ncv, sigma);
  Eigen::VectorXd v0 = start_vector(n, static_cast<std::uint64_t>(round) + 1);
  if (Q.cols() > 0) v0 -= Q * (Q.transpose() * mass.cwiseProduct(v0));
  solver.init(v0.data());
  const Index converged = solver.compute(Spectra::SortRule::LargestMagn, options.max_restarts, options.tolerance);
  summary->lanczos_operations += solver.num_operations();
  if (solver.info() != Spectra::CompInfo::Successful) {
    return fail(summary, fmt::format("Spectra shift-invert Lanczos did not converge: {} of {} eigenpairs after {} "
                                     "restarts (round {}, n = {}, ncv = {}, σ = {:.3e}, tolerance {:.1e})",
                                     converged, need, solver.num_iterations(), round, n, ncv, sigma,
                                     options.tolerance));
  }
  const Eigen::VectorXd new_values = solver.eigenvalues();
  Matrix<double> new_vectors = solver.eigenvectors();
  for (Index j = 0; j < new_vectors.cols(); ++j) {
    Eigen::VectorXd v = new_vectors.col(j);
    if (Q.cols() > 0) v -= Q * (Q.transpose() * mass.cwiseProduct(v));
    new_vectors.col(j) = v / std::sqrt(v.dot(mass.cwiseProduct(v)));
  }
  const Index f = Q.cols();
  Q.conservativeResize(n, f + new_vectors.cols());
  Q.rightCols(new_vectors.cols()) = new_vectors;
  for (Index j = 0; j < new_values.size(); ++j) found->values.push_back(new_values[j]);
  return true;
}

// The inertia check after a round: the eigenvalues below τ, just above the
// count-th smallest found, counted from LDLᵀ(L − τM), minus those found, in
// *missing (0 when none was missed). False, with the summary's status set,
// when the count fails or more rounds than options.max_deflation_rounds
// would be needed.
bool count_missing(const SparseMatrix<double>& L, const Eigen::VectorXd& mass, const std::vector<double>& values,
                   Index count, double sigma, Index round, const SpectralOptions& options, Index* missing,
                   SpectralSummary* summary) {
  std::vector<double> sorted = values;
  std::sort(sorted.begin(), sorted.end());
  const double lambda = sorted[static_cast<std::size_t>(count - 1)];
  double tau = lambda + options.inertia_margin * (lambda - sigma);
  Index below = count_below(L, mass, tau);
  if (below < 0) {  // τ hit an eigenvalue of a leading block: move it a little
    tau += options.inertia_margin * (lambda - sigma);
    below = count_below(L, mass, tau);
  }
  if (below < 0) {
    return fail(summary, fmt::format("inertia check: LDLᵀ of L − τM (τ = {:.6e}) hit a zero pivot", tau));
  }
  const Index found = std::count_if(values.begin(), values.end(), [tau](double v) { return v < tau; });
  *missing = 0;
  if (below <= found) return true;
  if (round + 1 > options.max_deflation_rounds) {
    return fail(summary, fmt::format("{} eigenvalues lie below τ = {:.6e} but only {} were found after {} "
                                     "deflation rounds (max_deflation_rounds)",
                                     below, tau, found, round));
  }
  *missing = below - found;
  return true;
}

// The `count` smallest of the found pairs, ties in the order found
// (finish_pairs sorts and normalises them).
Eigenpairs keep_smallest(FoundPairs found, Index count) {
  const std::vector<double>& values = found.values;
  std::vector<Index> order(values.size());
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(), [&values](Index a, Index b) { return values[a] < values[b]; });
  Eigenpairs kept;
  kept.values.resize(count);
  kept.vectors.resize(found.Q.rows(), count);
  for (Index j = 0; j < count; ++j) {
    kept.values[j] = values[order[j]];
    kept.vectors.col(j) = found.Q.col(order[j]);
  }
  return kept;
}

// Shift-invert Lanczos (Spectra), in rounds: Lanczos from one start vector
// finds one vector per eigenspace in exact arithmetic, so a repeated
// eigenvalue (a symmetric shape) may come back with too few copies. After each
// round the inertia of L − τM, τ just above the count-th eigenvalue, says how
// many eigenvalues lie below τ; if some were missed, the next round runs on
// the operator with the found vectors deflated and asks for the missing ones.
bool sparse_pairs(const SparseMatrix<double>& L, const Eigen::VectorXd& mass, Index count, double sigma,
                  const SpectralOptions& options, Eigenpairs* out, SpectralSummary* summary) {
  const Index n = L.rows();
  qpreduce::Timer timer;
  ShiftInvertOp op(L, mass, sigma, options.backend);
  summary->factorize_seconds = timer.seconds();
  if (!op.ok()) {
    return fail(summary, fmt::format("factoring L − σM (σ = {:.3e}, n = {}) failed: {}", sigma, n, op.message()));
  }
  timer.reset();
  DiagonalOp mop(mass);
  FoundPairs found{Matrix<double>(n, 0), {}};
  Index need = count;
  for (Index round = 0;; ++round) {
    if (!lanczos_round(op, mop, mass, need, sigma, round, options, &found, summary)) return false;
    summary->deflation_rounds = round;
    if (!options.verify_with_inertia) break;
    Index missing = 0;
    if (!count_missing(L, mass, found.values, count, sigma, round, options, &missing, summary)) return false;
    if (missing == 0) break;
    need = missing;
  }
  summary->eigen_seconds = timer.seconds();
  *out = keep_smallest(std::move(found), count);
  return true;
}

}  // namespace

namespace detail {

// One connected operator; σ < 0. Shared by laplacian_eigenpairs and the
// per-component embedding.
SpectralSummary eigenpairs_with_shift(const SparseMatrix<double>& L, const Eigen::VectorXd& mass, Index count,
                                      double sigma, const SpectralOptions& options, Eigenpairs* out) {
  qpreduce::Timer total;
  SpectralSummary summary;
  summary.components = 1;
  const Index n = L.rows();
  Eigenpairs pairs;
  if (n <= options.dense_max_size || n <= std::max(2 * count + 1, options.min_lanczos_vectors)) {
    qpreduce::Timer timer;
    dense_pairs(L, mass, count, &pairs);
    summary.eigen_seconds = timer.seconds();
  } else if (!sparse_pairs(L, mass, count, sigma, options, &pairs, &summary)) {
    summary.total_seconds = total.seconds();
    return summary;
  }
  summary.max_relative_residual = finish_pairs(L, mass, &pairs);
  summary.eigenpairs = pairs.values.size();
  summary.status = Status::Success;
  *out = std::move(pairs);
  summary.total_seconds = total.seconds();
  return summary;
}

// Non-null modes of one connected component, scaled by 1/√λ: n_c × (≤ K).
SpectralSummary component_embedding(const VerticesRef& V, const SparseMatrix<double>& L, const Eigen::VectorXd& mass,
                                    const std::vector<Index>& vertices, const SpectralOptions& options,
                                    Matrix<double>* coordinates) {
  const Index nc = static_cast<Index>(vertices.size());
  std::vector<int> local(static_cast<std::size_t>(L.rows()), -1);
  for (Index i = 0; i < nc; ++i) local[vertices[i]] = static_cast<int>(i);
  std::vector<Eigen::Triplet<double, int>> entries;
  Eigen::VectorXd mc(nc);
  for (Index i = 0; i < nc; ++i) {
    mc[i] = mass[vertices[i]];
    for (SparseMatrix<double>::InnerIterator it(L, vertices[i]); it; ++it) {
      const int r = local[it.row()];
      if (r >= 0) entries.emplace_back(r, static_cast<int>(i), it.value());
    }
  }
  SparseMatrix<double> Lc(nc, nc);
  Lc.setFromTriplets(entries.begin(), entries.end());
  if (!(mc.array() > 0.0).all()) {
    throw std::invalid_argument("spectral_embedding: a vertex of an element component has zero mass");
  }
  const Index count = std::min(options.eigenvectors + 1, nc);
  const double diagonal = subset_diagonal(V, vertices);
  const double sigma = -options.shift_scale / std::max(diagonal * diagonal, std::numeric_limits<double>::min());
  Eigenpairs pairs;
  SpectralSummary summary = eigenpairs_with_shift(Lc, mc, count, sigma, options, &pairs);
  if (!summary.ok()) return summary;
  const double zero = options.zero_tolerance * Lc.diagonal().sum() / mc.sum();
  coordinates->setZero(nc, options.eigenvectors);
  Index column = 0;
  for (Index j = 0; j < pairs.values.size() && column < options.eigenvectors; ++j) {
    if (pairs.values[j] <= zero) continue;
    coordinates->col(column++) = pairs.vectors.col(j) / std::sqrt(pairs.values[j]);
  }
  return summary;
}

void accumulate(SpectralSummary* into, const SpectralSummary& part) {
  into->components += part.components;
  into->eigenpairs += part.eigenpairs;
  into->lanczos_operations += part.lanczos_operations;
  into->deflation_rounds = std::max(into->deflation_rounds, part.deflation_rounds);
  into->max_relative_residual = std::max(into->max_relative_residual, part.max_relative_residual);
  into->factorize_seconds += part.factorize_seconds;
  into->eigen_seconds += part.eigen_seconds;
  into->total_seconds += part.total_seconds;
}

}  // namespace detail

SpectralSummary laplacian_eigenpairs(const SparseMatrix<double>& L, const Eigen::VectorXd& mass, Index count,
                                     double sigma, const SpectralOptions& options, Eigenpairs* out) {
  std::string why;
  if (!options.is_valid(&why)) throw std::invalid_argument("laplacian_eigenpairs: " + why);
  qpreduce::check_size("laplacian_eigenpairs: L columns", L.rows(), L.cols());
  qpreduce::check_size("laplacian_eigenpairs: mass size", L.rows(), mass.size());
  if (!(mass.array() > 0.0).all() || !mass.allFinite()) {
    throw std::invalid_argument("laplacian_eigenpairs: mass must be positive and finite");
  }
  if (count < 1 || count > L.rows()) {
    throw std::invalid_argument(
        fmt::format("laplacian_eigenpairs: count must lie in [1, {}], got {}", L.rows(), count));
  }
  if (!(sigma < 0.0) || !std::isfinite(sigma)) {
    throw std::invalid_argument(fmt::format("laplacian_eigenpairs: σ must be negative, got {}", sigma));
  }
  qpreduce::check_finite("laplacian_eigenpairs: L", L);
  if (!out) throw std::invalid_argument("laplacian_eigenpairs: out is null");
  return detail::eigenpairs_with_shift(L, mass, count, sigma, options, out);
}

SpectralSummary spectral_embedding(const VerticesRef& V, const SparseMatrix<double>& L, const Eigen::VectorXd& mass,
                                   const MeshComponents& components, const SpectralOptions& options,
                                   Matrix<double>* embedding) {
  qpreduce::Timer total;
  std::string why;
  if (!options.is_valid(&why)) throw std::invalid_argument("spectral_embedding: " + why);
  const Index n = V.rows();
  qpreduce::check_size("spectral_embedding: L rows", n, L.rows());
  qpreduce::check_size("spectral_embedding: mass size", n, mass.size());
  qpreduce::check_size("spectral_embedding: components' vertex count", n,
                               static_cast<Index>(components.vertex_component.size()));
  if (!embedding) throw std::invalid_argument("spectral_embedding: embedding is null");
  Matrix<double> result = Matrix<double>::Zero(n, options.eigenvectors);
  SpectralSummary summary;
  const std::vector<std::vector<Index>> lists = components.vertex_lists();
  for (Index c = 0; c < components.element_components; ++c) {
    Matrix<double> coordinates;
    const SpectralSummary part = detail::component_embedding(V, L, mass, lists[c], options, &coordinates);
    detail::accumulate(&summary, part);
    if (!part.ok()) {
      summary.status = part.status;
      summary.message = fmt::format("component {} ({} vertices): {}", c, lists[c].size(), part.message);
      summary.total_seconds = total.seconds();
      return summary;
    }
    for (std::size_t i = 0; i < lists[c].size(); ++i) result.row(lists[c][i]) = coordinates.row(static_cast<Index>(i));
  }
  summary.status = Status::Success;
  *embedding = std::move(result);
  summary.total_seconds = total.seconds();
  return summary;
}

void SpectralSummary::add_details(Report* out) const {
  out->add("components", components)
      .add("eigenpairs", eigenpairs)
      .add("lanczos_operations", lanczos_operations)
      .add("deflation_rounds", deflation_rounds)
      .add("max_relative_residual", max_relative_residual)
      .add("factorize_seconds", factorize_seconds)
      .add("eigen_seconds", eigen_seconds)
      .add("total_seconds", total_seconds);
}

}  // namespace qpreduce::deform
