// Phase 1 by elimination when A_z is a scaled selection (phase_one.h): the
// selected coordinates are known, the others solve one f × f system.
#include "blas.h"
#include "phase_one.h"

#include <Eigen/Cholesky>
#include <fmt/format.h>

#include <cmath>

namespace qpreduce::detail {

std::optional<ScaledSelection> scaled_selection(const Matrix<double>& Az) {
  const Index m = Az.rows(), d = Az.cols();
  if (m == 0 || m > d) return std::nullopt;
  ScaledSelection sel;
  sel.cols.assign(static_cast<size_t>(m), -1);
  sel.inv_scale.resize(m);
  std::vector<char> taken(static_cast<size_t>(d), 0);
  for (Index j = 0; j < d; ++j) {  // column by column: A_z is column-major
    for (Index i = 0; i < m; ++i) {
      const double a = Az(i, j);
      if (a == 0.0) continue;
      if (sel.cols[static_cast<size_t>(i)] >= 0 || taken[static_cast<size_t>(j)]) return std::nullopt;
      sel.cols[static_cast<size_t>(i)] = j;
      sel.inv_scale(i) = 1.0 / a;
      taken[static_cast<size_t>(j)] = 1;
    }
  }
  for (Index i = 0; i < m; ++i)
    if (sel.cols[static_cast<size_t>(i)] < 0) return std::nullopt;
  sel.free.reserve(static_cast<size_t>(d - m));
  for (Index j = 0; j < d; ++j)
    if (!taken[static_cast<size_t>(j)]) sel.free.push_back(j);
  return sel;
}

bool elimination_pays(Index d, Index m, Index k, bool prepared) {
  const double dd = static_cast<double>(d), mm = static_cast<double>(m), kk = static_cast<double>(k);
  const double f = dd - mm;
  // Cholesky of H_FF, its two triangular solves on f × (m + k), H_FC·X_C.
  const double elimination = f * f * f / 3.0 + 2.0 * f * f * (mm + kk) + f * mm * kk;
  // Y' = M0·Aᵀ and M_g (d²·m each), T = Y'·Σ⁻¹ (d·m²), Σ⁻¹ and the
  // curvature test's factor (m³ each), and the per-solver part if not made
  // (an eigendecomposition and M0, about 10·d³).
  const double range = 2.0 * dd * dd * mm + dd * mm * mm + 2.0 * mm * mm * mm + (prepared ? 0.0 : 10.0 * dd * dd * dd);
  return elimination < range;
}

std::shared_ptr<const PhaseOneOperator> eliminated_phase_one(const Matrix<double>& Hzz, const Matrix<double>& G,
                                                             const Matrix<double>& Ay, ScaledSelection sel,
                                                             const ConstraintOptions& options,
                                                             ConstraintSummary* summary) {
  using MatD = Matrix<double>;
  const Index d = Hzz.rows(), m = static_cast<Index>(sel.cols.size()), f = d - m, k = Ay.cols();
  const auto& C = sel.cols;
  const auto& F = sel.free;
  // H_FF, Jacobi-scaled (D = diag(H_FF)^(−1/2)), and H_FC.
  Eigen::VectorXd s(f);
  for (Index a = 0; a < f; ++a) {
    const double h = Hzz(F[static_cast<size_t>(a)], F[static_cast<size_t>(a)]);
    if (!(h > 0.0) || !std::isfinite(h)) return nullptr;
    s(a) = 1.0 / std::sqrt(h);
  }
  MatD Hff(f, f), Hfc(f, m);
  for (Index b = 0; b < f; ++b)
    for (Index a = 0; a < f; ++a) Hff(a, b) = s(a) * Hzz(F[static_cast<size_t>(a)], F[static_cast<size_t>(b)]) * s(b);
  for (Index i = 0; i < m; ++i)
    for (Index a = 0; a < f; ++a) Hfc(a, i) = Hzz(F[static_cast<size_t>(a)], C[static_cast<size_t>(i)]);
  const Eigen::LLT<MatD> llt(0.5 * (Hff + Hff.transpose()));
  double condition = 1.0;
  if (f > 0) {
    if (llt.info() != Eigen::Success) return nullptr;
    const Eigen::VectorXd piv = llt.matrixLLT().diagonal().cwiseAbs2();
    condition = piv.maxCoeff() / piv.minCoeff();  // a lower bound of cond(H̄_FF)
    if (!(std::isfinite(condition) && condition * options.rank_tolerance < 1e-2)) return nullptr;
  }
  // X_C = diag(1/a)·[I, −A_y]; the right-hand side [0, G_F] − H_FC·X_C.
  MatD XcY = -(sel.inv_scale.asDiagonal() * Ay);  // m × k
  MatD rhs(f, m + k);
  rhs.leftCols(m) = -(Hfc * sel.inv_scale.asDiagonal());
  for (Index a = 0; a < f; ++a) rhs.row(a).tail(k) = G.row(F[static_cast<size_t>(a)]);
  blas_gemm(false, false, -1.0, Hfc, XcY, 1.0, rhs.rightCols(k));
  // X_F = D·H̄_FF⁻¹·D·rhs.
  rhs = s.asDiagonal() * rhs;
  llt.solveInPlace(rhs);
  rhs = s.asDiagonal() * rhs;
  MatD Mb = MatD::Zero(d, m), MY(d, k);
  for (Index i = 0; i < m; ++i) {
    Mb(C[static_cast<size_t>(i)], i) = sel.inv_scale(i);
    MY.row(C[static_cast<size_t>(i)]) = XcY.row(i);
  }
  for (Index a = 0; a < f; ++a) {
    Mb.row(F[static_cast<size_t>(a)]) = rhs.row(a).head(m);
    MY.row(F[static_cast<size_t>(a)]) = rhs.row(a).tail(k);
  }
  if (!Mb.allFinite() || !MY.allFinite()) return nullptr;
  const double a_max = sel.inv_scale.cwiseAbs().cwiseInverse().maxCoeff();
  const double a_min = sel.inv_scale.cwiseAbs().cwiseInverse().minCoeff();
  summary->m = m;
  summary->rank = m;
  summary->condition = a_max / a_min;
  summary->status = Status::Success;
  summary->message = fmt::format(
      "{} hard constraints, rank {}: the {} selected coordinates eliminated, the other {} solved", m, m, m, f);
  return std::make_shared<ExplicitPhaseOne>(std::move(Mb), std::move(MY), std::move(sel));
}

}  // namespace qpreduce::detail
