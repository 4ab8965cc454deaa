// The fused rounds' operators, formed once per handle set (fused_form.h).
#include "fused_form.h"

#include "blas.h"
#include "simd_kernels.h"

#include "qpreduce/checks.h"

#include <Eigen/Eigenvalues>
#include <Spectra/SymEigsSolver.h>
#include <fmt/format.h>

#include <cmath>
#include <cstring>
#include <memory>

namespace qpreduce::detail {
namespace {

using MatD = Matrix<double>;
using MatF = Matrix<float>;

// Columns per block when the fast path forms F_y and its float copy: a
// q × 32 double block stays in L2 until it is copied (q = 9d ≤ 1000 →
// ≤ 256 KiB).
constexpr Index kColumnBlock = 32;

// Same shape and the same bits.
template <typename T>
bool same_matrix(const Matrix<T>& a, const Matrix<T>& b) {
  return a.rows() == b.rows() && a.cols() == b.cols() &&
         (a.size() == 0 || std::memcmp(a.data(), b.data(), sizeof(T) * static_cast<size_t>(a.size())) == 0);
}

// Forgets what was formed from C0 and G_y (F₀ and the curvature test).
void invalidate_base(FusedModel& M) {
  M.factored_rounds.base_valid = false;
  M.curvature = detail::CurvatureTest{};
}

// Whether λ_max(Q) ≤ ε for Q = −F₀ + U·R (CurvatureTest); false also when
// the test does not apply (then Lanczos decides).
bool curvature_within_floor(const detail::CurvatureTest& ct, const MatD& U, const MatD& R) {
  const Index mu = R.rows(), k = R.cols();
  if (mu == 0) return true;
  // [G, R·U] = R·[Rᵀ, U] (μ × 2μ), G = R·Rᵀ.
  MatD RtU(k, 2 * mu), GRU(mu, 2 * mu);
  RtU.leftCols(mu) = R.transpose();
  RtU.rightCols(mu) = U;
  detail::blas_gemm(false, false, 1.0, R, RtU, 0.0, GRU);
  const auto G = GRU.leftCols(mu), RU = GRU.rightCols(mu);
  // An orthonormal basis R̂ = Pᵀ·R of R's rows from G = Πᵀ·L·D·Lᵀ·Π (pivoted
  // LDLᵀ, the largest pivot first): Pᵀ = D_r^(−1/2)·(L⁻¹·Π)'s first r rows,
  // the pivots above kRowRank·D₀.
  const Eigen::LDLT<MatD> rows(G);
  const auto& pivots = rows.vectorD();
  if (!(pivots(0) > 0.0)) return false;
  Index r = 0;
  while (r < mu && pivots(r) > detail::CurvatureTest::kRowRank * pivots(0)) ++r;
  MatD Pt = rows.transpositionsP() * MatD::Identity(mu, mu);
  rows.matrixL().solveInPlace(Pt);
  const MatD P = (pivots.head(r).cwiseSqrt().cwiseInverse().asDiagonal() * Pt.topRows(r)).transpose();
  // U·R = R̂ᵀ·M·R̂ with M = R̂·U·R·R̂ᵀ = (Pᵀ·R·U)·(G·P) (r × r), when U lies in
  // the span of Rᵀ — ‖U − R̂ᵀR̂·U‖² = ‖U‖² − ‖R̂·U‖² (R̂ᵀR̂ projects) — and M
  // is symmetric, both to kFactorFit.
  const MatD PRU = P.transpose() * RU;
  MatD M = PRU * (G * P);
  const double fit = detail::CurvatureTest::kFactorFit, u2 = U.squaredNorm();
  if (!(u2 - PRU.squaredNorm() <= fit * fit * u2) || !((M - M.transpose()).norm() <= fit * M.norm())) return false;
  M = 0.5 * (M + M.transpose()).eval();
  // W = R̂·(F₀ + εI)⁻¹·R̂ᵀ = YᵀY with Y = L⁻¹·Rᵀ·P (k × r, the one O(k²·r)
  // step); W = L_W·L_Wᵀ, and λ_max(Q) ≤ ε ⟺ λ_max(L_Wᵀ·M·L_W) ≤ 1.
  MatD Y(k, r);
  detail::blas_gemm(false, false, 1.0, RtU.leftCols(mu), P, 0.0, Y);
  detail::blas_lower_solve(ct.factor, Y);
  MatD W(r, r);
  detail::blas_gemm(true, false, 1.0, Y, Y, 0.0, W);
  const Eigen::LLT<MatD> w(W);
  if (w.info() != Eigen::Success) return false;
  // λ_max(L_Wᵀ·M·L_W) < 1 ⟺ I − L_Wᵀ·M·L_W is positive definite.
  const MatD LW = w.matrixL();
  MatD C = -(LW.transpose() * M * LW);
  C.diagonal().array() += 1.0;
  return Eigen::LLT<MatD>(C).info() == Eigen::Success;
}

// U = G_z·T (q × μ) in double, or in float into factored_rounds.U_f (the
// returned matrix is then empty), with the multipliers folded in when the
// rounds correct for constraints on y (E not null): U = G_z·T + A_yᵀ·K
// (λ = K·(R·y − [b; 0]), phase_one.h), since then
//     F_y − A_yᵀΛ_y = F₀ − G_z·T·R − A_yᵀ·K·R = F₀ − U·R,
//     F_b − A_yᵀΛ_b = G_z·M_b + A_yᵀ·(K's first m columns) = U's first m columns.
// Sets F_b = U's first m columns; *U_float: U in double after a float one
// with E (for the curvature test).
MatD form_u(FusedModel& M, const detail::FactoredPhaseOne& phase1, const MatD& Gz, bool in_float,
            const detail::PhaseOneEnergy* E, MatD* U_float) {
  const Index q = Gz.rows(), m = phase1.Mb().cols(), mu = phase1.T().cols();
  MatD U;
  if (in_float) {
    form_gz_float(M, Gz);
    const MatF Tf = phase1.T().cast<float>();
    MatF& Uf = M.factored_rounds.U_f;
    Uf.resize(q, mu);
    detail::blas_gemm(false, false, 1.0, M.Gz_f, Tf, 0.0, Uf);
    if (E) {
      *U_float = Uf.cast<double>();
      detail::blas_gemm(true, false, 1.0, E->AyLy.topRows(m), phase1.K(), 1.0, *U_float);
      Uf = U_float->cast<float>();
      M.Fb = U_float->leftCols(m);
    } else {
      M.Fb = Uf.leftCols(m).cast<double>();
    }
  } else {
    U.resize(q, mu);
    detail::blas_gemm(false, false, 1.0, Gz, phase1.T(), 0.0, U);
    if (E) detail::blas_gemm(true, false, 1.0, E->AyLy.topRows(m), phase1.K(), 1.0, U);
    M.Fb = U.leftCols(m);
  }
  return U;
}

// Factored form: F₀ = C0 + G_y once per (C0, G_y); U and R per set.
void set_factored(FusedModel& M, const detail::FactoredPhaseOne& phase1, MatD U, FusedPrecision precision) {
  detail::FactoredRounds& fr = M.factored_rounds;
  form_factored_base(M);
  if (precision == FusedPrecision::Double) {
    fr.U = std::move(U);
    fr.U_f = fr.U.cast<float>();
  } else {
    fr.U = fr.U_f.cast<double>();  // the same operator for the float rounds' double references
  }
  M.float_set = precision == FusedPrecision::Float;
  fr.Rt = phase1.R().transpose();
  fr.Rt_f = fr.Rt.cast<float>();
  M.factored = true;
}

// Explicit form from the fast path: F_y = C0 + G_y − U·R, in column blocks
// that are still in cache for the float copy.
void set_explicit_fast(FusedModel& M, const detail::FactoredPhaseOne& phase1, const MatD& Gy, const MatD& U) {
  detail::ExplicitRounds& er = M.explicit_rounds;
  const Index q = Gy.rows(), k = Gy.cols();
  er.F.resize(q, k);
  er.F_f.resize(q, k);
  for (Index c0 = 0; c0 < k; c0 += kColumnBlock) {
    const Index w = std::min(kColumnBlock, k - c0);
    if (!Gy.middleCols(c0, w).allFinite()) check_finite("FusedAlternation::set: G_y", Gy);  // throws
    er.F.middleCols(c0, w) = M.C0.middleCols(c0, w) + Gy.middleCols(c0, w);
    detail::blas_gemm(false, false, -1.0, U, phase1.R().middleCols(c0, w), 1.0, er.F.middleCols(c0, w));
    er.F_f.middleCols(c0, w) = er.F.middleCols(c0, w).cast<float>();
  }
}

// Q·v = −(F_y′·v) for the Lanczos run of form_proximal_weights: F_y′ =
// F_y − A_yᵀΛ_y as the rounds now apply it (before D), in double, or in
// float after a Float set (whose U exists in float only).
class NegatedRounds {
 public:
  using Scalar = double;
  NegatedRounds(const FusedModel& M, Index k)
      : M_(M), k_(k), scratch_(M.rounds().scratch_size()), scratch_f_(scratch_.size()), xf_(k), yf_(k) {}
  Index rows() const { return k_; }
  Index cols() const { return k_; }
  void perform_op(const double* x, double* y) const {
    if (M_.float_set) {
      xf_ = Eigen::Map<const Vector<double>>(x, k_).cast<float>();
      yf_.setZero();
      M_.rounds().add_rows(xf_.data(), 0, k_, scratch_f_.data(), yf_.data());
      Eigen::Map<Vector<double>>(y, k_) = -yf_.cast<double>();
      return;
    }
    std::fill(y, y + k_, 0.0);
    M_.rounds().add_rows(x, 0, k_, scratch_.data(), y);
    for (Index i = 0; i < k_; ++i) y[i] = -y[i];
  }

 private:
  const FusedModel& M_;
  Index k_;
  mutable Vector<double> scratch_;
  mutable Vector<float> scratch_f_, xf_, yf_;
};

// λ_max(Q) from a Lanczos run (Spectra), raised by 1 % (a Ritz value
// approaches λ_max from below; float rounds carry ~1e-7 relative error); NaN
// when Lanczos does not converge.
double largest_eigenvalue(const FusedModel& M, Index k) {
  if (k < 3) return std::numeric_limits<double>::quiet_NaN();
  NegatedRounds op(M, k);
  Spectra::SymEigsSolver<NegatedRounds> eigs(op, 1, std::min<Index>(k, 24));
  const Vector<double> start = Vector<double>::Ones(k);  // deterministic
  eigs.init(start.data());
  eigs.compute(Spectra::SortRule::LargestAlge, 300, 1e-6);
  if (eigs.info() != Spectra::CompInfo::Successful) return std::numeric_limits<double>::quiet_NaN();
  const double theta = eigs.eigenvalues()(0);
  return theta + 0.01 * std::abs(theta);
}

// Block Gershgorin bound of Q (blocks of s entries; needs Q explicitly):
// D_a = λ_max(sym Q_aa) + Σ_{b≠a} ‖Q_ab‖_F, clamped at 0, gives Q ⪯ diag(D_a·I)
// since 2x_aᵀQ_ab x_b ≤ ‖Q_ab‖(‖x_a‖² + ‖x_b‖²). Small for blocks far from
// the constraints, where the scalar λ_max would hold back the whole vector.
Vector<double> block_gershgorin(const MatD& Q, Index s) {
  const Index blocks = Q.rows() / s;
  Vector<double> D(blocks);
  Eigen::SelfAdjointEigenSolver<MatD> eig;
  for (Index a = 0; a < blocks; ++a) {
    const MatD Qaa = 0.5 * (Q.block(s * a, s * a, s, s) + Q.block(s * a, s * a, s, s).transpose());
    eig.compute(Qaa, Eigen::EigenvaluesOnly);
    double Da = eig.eigenvalues()(s - 1);
    for (Index b = 0; b < blocks; ++b)
      if (b != a) Da += 0.5 * (Q.block(s * a, s * b, s, s).norm() + Q.block(s * b, s * a, s, s).norm());
    D(a) = std::max(Da, 0.0);
  }
  return D;
}

// The proximal weights D ⪰ Q of the corrected rounds: zero when Q ⪯ 0
// (λ_max ≤ 0: the corrected step descends as it is), which the curvature
// test settles when it applies (fast path: U in double, R; λ_max ≤ ε counts
// as ≤ 0, ε at round-off size); else the block Gershgorin weights (explicit
// form, blocks of M.block) or the scalar λ_max from a Lanczos run,
// whichever is smaller in total; a bound on ‖Q‖ when Lanczos fails.
void form_proximal_weights(FusedModel& M, Index k, const MatD* U, const MatD* R) {
  const Index s = M.block > 0 && k % M.block == 0 ? M.block : k;
  const Index blocks = k / s;
  if (U != nullptr && R != nullptr) form_curvature_test(M);
  const bool within_floor =
      U != nullptr && R != nullptr && M.curvature.usable() && curvature_within_floor(M.curvature, *U, *R);
  const double lambda = within_floor ? 0.0 : largest_eigenvalue(M, k);
  if (lambda <= 0.0) {
    M.proximal.setZero(blocks);
  } else {
    double scalar = lambda;
    if (!std::isfinite(scalar)) {  // ‖Q‖_F from Q's parts: safe, if slower rounds
      const auto& fr = M.factored_rounds;
      scalar = M.factored ? static_cast<double>(fr.F0_f.norm()) + static_cast<double>(fr.U_f.norm()) * fr.Rt.norm()
                          : M.explicit_rounds.F.norm();
    }
    M.proximal.setConstant(blocks, scalar);
    if (!M.factored && s < k) {
      const Vector<double> D = block_gershgorin(-M.explicit_rounds.F, s);
      if (D.sum() < M.proximal.sum()) M.proximal = D;
    }
  }
  M.proximal_entries.resize(k);
  for (Index a = 0; a < blocks; ++a) M.proximal_entries.segment(s * a, s).setConstant(M.proximal(a));
}

}  // namespace

void keep_inputs(FusedModel& M, const MatD& Gz, const MatD& Gy) {
  M.inputs_ready = false;
  if (!same_matrix(M.Gz, Gz)) {
    M.prep.reset();
    M.Gz = Gz;
  }
  if (!same_matrix(M.Gy, Gy)) {
    invalidate_base(M);
    M.Gy = Gy;
  }
  M.inputs_ready = true;
}

void form_c0(FusedModel& M, const std::shared_ptr<const detail::FixedCoordinatePrep>& prep, const MatD& Gz) {
  if (M.prep == prep) return;
  M.prep.reset();
  invalidate_base(M);
  check_finite("FusedAlternation: G_z", Gz);
  M.C0.resize(Gz.rows(), prep->P0.cols());
  detail::blas_gemm(false, false, 1.0, Gz, prep->P0, 0.0, M.C0);
  M.Gz_f.resize(0, 0);
  M.prep = prep;
}

// F₀ = C0 + G_y square, nonzero and symmetric to CurvatureTest::kSymmetry
// (relative, Frobenius): the test both the factored rounds' lower-triangle
// product and the curvature test rely on.
bool symmetric_to_round_off(const MatD& F0) {
  const double size = F0.norm();
  return F0.rows() == F0.cols() && size > 0.0 &&
         (F0 - F0.transpose()).norm() <= detail::CurvatureTest::kSymmetry * size;
}

void form_factored_base(FusedModel& M) {
  detail::FactoredRounds& fr = M.factored_rounds;
  if (fr.base_valid) return;
  check_finite("FusedAlternation::set: G_y", M.Gy);
  fr.F0 = M.C0 + M.Gy;
  fr.F0_f = fr.F0.cast<float>();
  fr.symmetric = symmetric_to_round_off(fr.F0);
  fr.base_valid = true;
}

void form_curvature_test(FusedModel& M) {
  detail::CurvatureTest& ct = M.curvature;
  if (ct.formed) return;
  ct.formed = true;
  ct.factor.resize(0, 0);
  const Index k = M.Gy.cols();
  if (M.Gy.rows() != k || k == 0 || !M.Gy.allFinite()) return;
  // The factored base's F₀ and its test when formed, else F₀ here.
  const detail::FactoredRounds& fr = M.factored_rounds;
  const bool from_base = fr.base_valid && fr.F0.rows() == k;
  if (from_base && !fr.symmetric) return;
  MatD F0 = from_base ? fr.F0 : MatD(M.C0 + M.Gy);
  if (!from_base && !symmetric_to_round_off(F0)) return;
  ct.floor = detail::CurvatureTest::kFloor * F0.norm();
  F0.diagonal().array() += ct.floor;
  Eigen::LLT<MatD> llt(F0);  // reads the lower triangle
  if (llt.info() != Eigen::Success || !llt.matrixLLT().allFinite()) return;
  ct.factor = llt.matrixLLT();
}

void form_gz_float(FusedModel& M, const MatD& Gz) {
  if (M.Gz_f.rows() != Gz.rows() || M.Gz_f.cols() != Gz.cols()) M.Gz_f = Gz.cast<float>();
}

void set_explicit_plain(FusedModel& M, const FixedCoordinateSolver<double>& phase1, const MatD& Gz, const MatD& Gy,
                        const detail::PhaseOneEnergy* E) {
  check_finite("FusedAlternation::set: G_z", Gz);
  check_finite("FusedAlternation::set: G_y", Gy);
  detail::ExplicitRounds& er = M.explicit_rounds;
  er.F = Gy;
  M.Fb.resize(Gz.rows(), phase1.m());
  detail::blas_gemm(false, false, 1.0, Gz, phase1.Mb(), 0.0, M.Fb);
  detail::blas_gemm(false, false, 1.0, Gz, phase1.MY(), 1.0, er.F);
  if (E) {
    const Index m = E->Lb.rows();
    const auto Ay = E->AyLy.topRows(m), Ly = E->AyLy.bottomRows(m);
    M.Fb.noalias() -= Ay.transpose() * E->Lb;
    er.F.noalias() -= Ay.transpose() * Ly;
  }
  er.F_f = er.F.cast<float>();
}

bool stiff_rotation_set(const FusedModel& M) {
  return M.q() == M.k() && M.k() % 9 == 0 && M.proximal.size() > 0 && M.proximal.maxCoeff() > 0.0;
}

const detail::PhaseOneEnergy* start_correction(FusedModel& M, const FixedCoordinateSolver<double>& phase1) {
  M.energy_seen = phase1.shared_energy_terms();
  M.energy.reset();
  M.proximal.resize(0);
  M.proximal_entries.resize(0);
  M.second_order = false;
  M.factored_rounds.shift.resize(0);
  if (!M.energy_seen || M.energy_seen->ay_zero || M.Gy.rows() != M.Gy.cols()) return nullptr;
  return M.energy_seen.get();
}

void finish_correction(FusedModel& M, const MatD* U, const MatD* R) {
  form_proximal_weights(M, M.k(), U, R);
  // Damped rounds (some w_j > 0) crawl on stiff sets: second-order steps
  // there, in the explicit double form, for blocks of 3 × 3.
  M.second_order = !M.factored && !M.float_set && stiff_rotation_set(M);
  if (M.proximal.maxCoeff() > 0.0) {
    if (M.factored) {
      M.factored_rounds.shift = M.proximal_entries;
    } else {
      M.explicit_rounds.F.diagonal() += M.proximal_entries;
      M.explicit_rounds.F_f = M.explicit_rounds.F.cast<float>();
    }
  }
  M.energy = M.energy_seen;
}

void set_fast_rounds(FusedModel& M, const detail::FactoredPhaseOne& fast, const detail::PhaseOneEnergy* E,
                     bool factored, FusedPrecision precision) {
  M.factored = false;
  M.float_set = false;
  const bool in_float = factored && precision == FusedPrecision::Float;
  MatD U_float;
  MatD U = form_u(M, fast, M.Gz, in_float, E, &U_float);
  if (factored) {
    set_factored(M, fast, std::move(U), precision);
  } else {
    set_explicit_fast(M, fast, M.Gy, U);
  }
  if (E) finish_correction(M, in_float ? &U_float : factored ? &M.factored_rounds.U : &U, &fast.R());
}

void size_workspace(const FusedModel& M, FusedWorkspace& W) {
  const Index q = M.q(), k = M.k(), mu = M.rounds().scratch_size();
  W.gb.resize(q);
  W.g.resize(q);
  W.gf.resize(q);
  W.yf.resize(k);
  W.y_ref.resize(k);
  W.dy.resize(k);
  W.Fy_ref.resize(q);
  W.ref_valid = false;  // the rounds' operator changed
  W.scratch.resize(mu);
  W.scratch_f.resize(mu);
}

}  // namespace qpreduce::detail
