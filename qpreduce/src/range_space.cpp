#include "range_space.h"

#include "blas.h"
#include "dense.h"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/QR>
#include <Eigen/SVD>
#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

namespace qpreduce::detail {

namespace {
using MatD = Matrix<double>;
}  // namespace

RangeSpace prepare_range_space(const MatD& H, double lift_tolerance, bool factored_terms) {
  RangeSpace rs;
  const Index p = H.rows();
  // D_s = diag(H)^(−1/2); a column without energy keeps the largest scale.
  const double max_diag = p > 0 ? H.diagonal().maxCoeff() : 0.0;
  rs.scale.resize(p);
  for (Index i = 0; i < p; ++i) {
    const double h = H(i, i);
    rs.scale(i) = h > std::numeric_limits<double>::epsilon() * max_diag ? 1.0 / std::sqrt(h)
                  : max_diag > 0                                          ? 1.0 / std::sqrt(max_diag)
                                                                          : 1.0;
  }
  rs.inv_scale = rs.scale.cwiseInverse();
  const MatD Hbar = rs.scale.asDiagonal() * H * rs.scale.asDiagonal();
  Eigen::VectorXd lambda;
  MatD V;
  if (!symmetric_eigen(MatD(0.5 * (Hbar + Hbar.transpose())), &lambda, &V)) {
    lambda.setConstant(p, std::numeric_limits<double>::quiet_NaN());  // the operators below come out NaN
    V.setZero(p, p);
  }
  rs.hbar_max = p > 0 ? std::max(lambda.maxCoeff(), std::numeric_limits<double>::min()) : 1.0;
  const double sigma = rs.hbar_max;
  Eigen::VectorXd inv(p);
  std::vector<Index> lifted;
  for (Index i = 0; i < p; ++i) {
    if (lambda(i) <= lift_tolerance * sigma) {
      lifted.push_back(i);
      inv(i) = 1.0 / sigma;
    } else {
      inv(i) = 1.0 / lambda(i);
    }
  }
  const MatD DV = rs.scale.asDiagonal() * V;  // D_s·V
  // M0 = W·Wᵀ with W = D_s·V·Λ̃^(−1/2) (every entry of Λ̃⁻¹ is positive), through the BLAS.
  const MatD W = DV * inv.cwiseSqrt().asDiagonal();
  rs.Minv0.resize(p, p);
  blas_gemm(false, true, 1.0, W, W, 0.0, rs.Minv0);
  rs.Minv0 = 0.5 * (rs.Minv0 + rs.Minv0.transpose()).eval();
  const Index nu = static_cast<Index>(lifted.size());
  rs.lift_cols.resize(p, nu);
  rs.lift_block.resize(nu);
  for (Index j = 0; j < nu; ++j) {
    const Index i = lifted[static_cast<size_t>(j)];
    rs.lift_cols.col(j) = DV.col(i) / sigma;
    rs.lift_block(j) = -lambda(i) / (sigma * (sigma - lambda(i)));  // = 1/σ − 1/(σ − λ), without cancellation
  }
  if (factored_terms) {
    // T_j = (D_sV)·Λ̃⁻ʲ·(D_sV)ᵀ.
    const MatD DV2 = DV * inv.array().square().matrix().asDiagonal();
    const MatD DV3 = DV2 * inv.asDiagonal();
    rs.T2.resize(p, p);
    rs.T3.resize(p, p);
    blas_gemm(false, true, 1.0, DV2, DV, 0.0, rs.T2);
    blas_gemm(false, true, 1.0, DV3, DV, 0.0, rs.T3);
    rs.T2 = 0.5 * (rs.T2 + rs.T2.transpose()).eval();
    rs.T3 = 0.5 * (rs.T3 + rs.T3.transpose()).eval();
    rs.inv_fro2 = inv.squaredNorm();
  }
  return rs;
}

namespace {

// Ā's nonzero columns and whether Ā is a scaled selection (every row has one
// nonzero, no two rows in the same column; then row_col[i] is row i's column).
struct NonzeroPattern {
  std::vector<Index> cols;
  std::vector<Index> row_col;
  bool selection = false;
};

NonzeroPattern nonzero_pattern(const MatD& Abar) {
  const Index m = Abar.rows(), p = Abar.cols();
  NonzeroPattern pat;
  std::vector<Index> row_count(static_cast<size_t>(m), 0);
  pat.row_col.assign(static_cast<size_t>(m), 0);
  Index nnz = 0;
  for (Index j = 0; j < p; ++j) {
    Index count = 0;
    for (Index i = 0; i < m; ++i) {
      if (Abar(i, j) == 0.0) continue;
      ++count;
      ++row_count[static_cast<size_t>(i)];
      pat.row_col[static_cast<size_t>(i)] = j;
    }
    if (count > 0) pat.cols.push_back(j);
    nnz += count;
  }
  pat.selection = m > 0 && nnz == m && static_cast<Index>(pat.cols.size()) == m &&
                  std::all_of(row_count.begin(), row_count.end(), [](Index c) { return c == 1; });
  return pat;
}

Index default_rank(const MatD& Abar, const NonzeroPattern& pat) {
  const Index m = Abar.rows(), p = Abar.cols();
  if (m == 0 || pat.cols.empty()) return 0;
  Eigen::ColPivHouseholderQR<MatD> qr(Abar(Eigen::all, pat.cols));
  qr.setThreshold(std::numeric_limits<double>::epsilon() * static_cast<double>(std::min(m, p)));
  return qr.rank();
}

}  // namespace

Index default_rank(const MatD& Abar) { return default_rank(Abar, nonzero_pattern(Abar)); }

bool bordered_inverse(const MatD& S11, const MatD& S12, const Eigen::VectorXd& lift_block, MatD* Sinv) {
  const Index m = S11.rows(), nu = S12.cols(), q = m + nu;
  auto symmetric_part = [](const MatD& S) -> MatD { return 0.5 * (S + S.transpose()); };
  if (!S11.allFinite() || !S12.allFinite()) return false;
  MatD& Si = *Sinv;
  Si.resize(q, q);
  Eigen::LLT<MatD> llt11;
  if (m > 0) {
    llt11.compute(symmetric_part(S11));
    if (llt11.info() != Eigen::Success) return false;
    Si.topLeftCorner(m, m) = llt11.solve(MatD::Identity(m, m));
  }
  if (nu > 0) {
    const MatD E = m > 0 ? MatD(llt11.solve(S12)) : MatD(0, nu);
    MatD N = S12.transpose() * E;
    N.diagonal() -= lift_block;
    const Eigen::LLT<MatD> llt2(symmetric_part(N));
    if (llt2.info() != Eigen::Success) return false;
    const MatD Ninv = llt2.solve(MatD::Identity(nu, nu));
    const MatD EN = E * Ninv;
    Si.topLeftCorner(m, m).noalias() -= EN * E.transpose();
    Si.topRightCorner(m, nu) = EN;
    Si.bottomLeftCorner(nu, m) = EN.transpose();
    Si.bottomRightCorner(nu, nu) = -Ninv;
  }
  Si = symmetric_part(Si);
  return Si.allFinite();
}

bool range_space_rank(const RangeSpace& rs, const MatD& A, const ConstraintOptions& options,
                      ConstraintSummary* summary) {
  const Index m = A.rows();
  summary->m = m;
  const MatD Abar = A * rs.scale.asDiagonal();
  const NonzeroPattern pat = nonzero_pattern(Abar);
  if (options.soft) {
    summary->rank = default_rank(Abar, pat);
    summary->condition = 0.0;
    summary->status = Status::Success;
    summary->message = fmt::format("{} soft constraints, δ = {:.3g}", m, options.delta);
    return true;
  }
  // Hard constraints: the fast path needs full row rank; the null-space
  // method handles the rest (least squares).
  Index r = 0;
  double condition = 0.0;
  if (pat.selection) {
    double sv_max = 0.0, sv_min = 0.0;
    for (Index i = 0; i < m; ++i) {
      const double v = std::abs(Abar(i, pat.row_col[static_cast<size_t>(i)]));
      sv_max = i == 0 ? v : std::max(sv_max, v);
      sv_min = i == 0 ? v : std::min(sv_min, v);
    }
    // As ColPivHouseholderQR::rank: |R_ii| above threshold × max |R_ii|.
    for (Index i = 0; i < m; ++i)
      r += std::abs(Abar(i, pat.row_col[static_cast<size_t>(i)])) > options.rank_tolerance * sv_max;
    condition = sv_max / sv_min;
  } else if (m > 0 && !pat.cols.empty()) {
    // (Eigen's QR of a matrix without columns crashes: m = 0 or Ā = 0 skips it.)
    Eigen::ColPivHouseholderQR<MatD> qr;  // of Āᵀ's nonzero rows, |J| × m
    qr.setThreshold(options.rank_tolerance);
    qr.compute(Abar(Eigen::all, pat.cols).transpose());
    if (qr.matrixQR().diagonal().cwiseAbs().maxCoeff() > 0) r = qr.rank();
    if (r == m) {
      // Ā's singular values are R's (ĀᵀΠ = QR).
      const MatD R = qr.matrixQR().topRows(m).template triangularView<Eigen::Upper>();
      const Eigen::JacobiSVD<MatD> svd(R);
      const auto& sv = svd.singularValues();
      condition = sv(0) / sv(m - 1);
    }
  }
  if (r != m) return false;
  summary->rank = r;
  summary->condition = condition;
  summary->status = Status::Success;
  summary->message = fmt::format("{} hard constraints, rank {}", m, r);
  return true;
}

namespace {

// Y', Σ⁻¹ (bordered_inverse), T and M_g; false when Σ is singular or the
// condition bound fails (see the header).
bool bordered_operators(const RangeSpace& rs, const MatD& A, bool soft, double delta, double rank_tolerance,
                        RangeSpaceOperators* out) {
  const Index p = A.cols(), m = A.rows(), nu = rs.lift_cols.cols(), q = m + nu;
  MatD& Y = out->Y;  // Y' = [M0·Aᵀ, L]
  Y.resize(p, q);
  blas_gemm(false, true, 1.0, rs.Minv0, A, 0.0, Y.leftCols(m));
  Y.rightCols(nu) = rs.lift_cols;
  MatD S11(m, m);
  blas_gemm(false, false, 1.0, A, Y.leftCols(m), 0.0, S11);
  if (soft) S11.diagonal().array() += 1.0 / (2.0 * delta);
  MatD& Sinv = out->Sinv;
  if (!bordered_inverse(S11, A * rs.lift_cols, rs.lift_block, &Sinv)) return false;
  MatD& T = out->T;
  T.resize(p, q);
  blas_gemm(false, false, 1.0, Y, Sinv, 0.0, T);
  // M_g = M0 − T·Y'ᵀ (symmetric; its lower triangle is read).
  MatD& Mg = out->Mg;
  Mg = rs.Minv0;
  blas_gemm(false, true, -1.0, T, Y, 1.0, Mg);
  // Accept only when the null-space method would call the problem
  // nonsingular: with M̄_g = D_s⁻¹M_gD_s⁻¹, ‖M̄_g‖₂ = 1/λ_min on the
  // constraint set (hard) or 1/λ_min(K̄) (soft), and λ_max there is at most
  // λ_max(H̄) (+ 2δ‖Ā‖² for soft).
  // (A NaN or Inf in M_g makes the bound non-finite, so this also checks M_g.)
  double norm2 = 0.0;
  for (Index j = 0; j < p; ++j) {
    const double sj = rs.inv_scale(j);
    const double diag = Mg(j, j) * sj * sj;
    double col = 0.0;
    for (Index i = j + 1; i < p; ++i) {
      const double v = Mg(i, j) * rs.inv_scale(i);
      col += v * v;
    }
    norm2 += diag * diag + 2.0 * col * sj * sj;
  }
  const double lambda_up = rs.hbar_max + (soft ? 2.0 * delta * (A * rs.scale.asDiagonal()).squaredNorm() : 0.0);
  const double cond_bound = lambda_up * std::sqrt(norm2);
  if (!std::isfinite(cond_bound) || !(cond_bound * rank_tolerance < 1.0)) return false;
  return T.allFinite();
}

}  // namespace

bool range_space_operators(const RangeSpace& rs, const MatD& A, const ConstraintOptions& options,
                           ConstraintSummary* summary, RangeSpaceOperators* out) {
  // Soft constraints with more rows than unknowns: the bordered form works
  // on m × m matrices (O(m³ + m²·p)), the null-space method on p × p ones
  // (H + 2δAᵀA, O(p³ + p²·m)); 3,000 point handles on the cactus's Phase 1
  // took 301 s here; the whole set_handles by the null-space method 3.7 s
  // (docs/robustness.md, "Soak").
  if (options.soft && A.rows() > A.cols()) {
    summary->m = A.rows();
    return false;
  }
  return range_space_rank(rs, A, options, summary) &&
         bordered_operators(rs, A, options.soft, options.soft ? options.delta : 0.0, options.rank_tolerance, out);
}

}  // namespace qpreduce::detail
