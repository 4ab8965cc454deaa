// FusedAlternation (alternating.h): Phase 1 folded into Phase 2's input,
// g = F_b·b + F_y·y, in the explicit or the factored form (fused_rounds.h).
#include "qpreduce/alternating.h"

#include "blas.h"
#include "fused_rounds.h"
#include "phase_one.h"
#include "round_product.h"
#include "round_stop.h"
#include "simd_kernels.h"

#include "qpreduce/support.h"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <Spectra/SymEigsSolver.h>
#include <fmt/format.h>

#include <omp.h>

#include <cmath>
#include <cstring>
#include <memory>
#include <optional>

namespace qpreduce {

bool AlternatingOptions::is_valid(std::string* why) const {
  if (iterations < 1) {
    if (why) *why = fmt::format("iterations must be at least 1, got {}", iterations);
    return false;
  }
  if (!(tolerance >= 0.0) || !std::isfinite(tolerance)) {
    if (why) *why = fmt::format("tolerance must be finite and ≥ 0, got {}", tolerance);
    return false;
  }
  if (!(time_budget >= 0.0) || !std::isfinite(time_budget)) {
    if (why) *why = fmt::format("time_budget must be finite and ≥ 0 seconds (0: none), got {}", time_budget);
    return false;
  }
  if (threads < 0) {
    if (why) *why = fmt::format("threads must be ≥ 0 (0: all), got {}", threads);
    return false;
  }
  if (parallel_min_entries < 0) {
    if (why) *why = fmt::format("parallel_min_entries must be ≥ 0, got {}", parallel_min_entries);
    return false;
  }
  if (anderson_window < 0 || anderson_window > AndersonAcceleration::kMaxWindow) {
    if (why) {
      *why = fmt::format("anderson_window must be in [0, {}] (0: plain rounds), got {}",
                         AndersonAcceleration::kMaxWindow, anderson_window);
    }
    return false;
  }
  return true;
}

const char* to_string(RoundStop stop) {
  switch (stop) {
    case RoundStop::RoundLimit: return "round limit";
    case RoundStop::Tolerance: return "tolerance";
    case RoundStop::TimeBudget: return "time budget";
  }
  return "unknown";
}

namespace {

using detail::FusedModel;
using detail::FusedWorkspace;
using detail::double_product;
using detail::difference_product;
using detail::kNoChange;
using detail::near_reference;
using detail::reference_product;
using detail::reference_stale;
using detail::round_product;
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

// Keeps copies of the inputs; a changed input invalidates what was formed from it.
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

// C0 = G_z·P0, once per (Phase 1 preparation, G_z).
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

// F₀ = C0 + G_y for the factored rounds (and its float copy), once per (C0, G_y).
void form_factored_base(FusedModel& M) {
  detail::FactoredRounds& fr = M.factored_rounds;
  if (fr.base_valid) return;
  check_finite("FusedAlternation::set: G_y", M.Gy);
  fr.F0 = M.C0 + M.Gy;
  fr.F0_f = fr.F0.cast<float>();
  fr.base_valid = true;
}

// The curvature test's factor L, F₀ + εI = LLᵀ (fused_rounds.h,
// CurvatureTest), once per (C0, G_y), for q = k; left empty when F₀ is not
// symmetric or F₀ + εI not positive definite. O(k³).
void form_curvature_test(FusedModel& M) {
  detail::CurvatureTest& ct = M.curvature;
  if (ct.formed) return;
  ct.formed = true;
  ct.factor.resize(0, 0);
  const Index k = M.Gy.cols();
  if (M.Gy.rows() != k || k == 0 || !M.Gy.allFinite()) return;
  MatD F0 = M.C0 + M.Gy;
  const double size = F0.norm();
  if (!(size > 0.0) || (F0 - F0.transpose()).norm() > detail::CurvatureTest::kSymmetry * size) return;
  ct.floor = detail::CurvatureTest::kFloor * size;
  F0.diagonal().array() += ct.floor;
  Eigen::LLT<MatD> llt(F0);  // reads the lower triangle
  if (llt.info() != Eigen::Success || !llt.matrixLLT().allFinite()) return;
  ct.factor = llt.matrixLLT();
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

// G_z's float copy unless it is current (form_c0 empties it).
void form_gz_float(FusedModel& M, const MatD& Gz) {
  if (M.Gz_f.rows() != Gz.rows() || M.Gz_f.cols() != Gz.cols()) M.Gz_f = Gz.cast<float>();
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
  fr.R = phase1.R();
  fr.R_f = fr.R.cast<float>();
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

// Explicit form from Phase 1's null-space method: F_b = G_z·M_b, F_y = G_z·M_Y + G_y,
// then F_b ← F_b − A_yᵀΛ_b, F_y ← F_y − A_yᵀΛ_y when E (constraints on y).
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
      scalar = M.factored ? static_cast<double>(fr.F0_f.norm()) + static_cast<double>(fr.U_f.norm()) * fr.R.norm()
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

// Damped rounds (some proximal weight > 0) on blocks of 3 × 3 with q = k:
// the stiff sets that second-order steps are for (once the weights are formed).
bool stiff_rotation_set(const FusedModel& M) {
  return M.q() == M.k() && M.k() % 9 == 0 && M.proximal.size() > 0 && M.proximal.maxCoeff() > 0.0;
}

// Constraints on y (alternating.h): the energy terms the rounds correct
// for — Phase 1 has them, A_y ≠ 0 and q = k — or null. Resets what the last
// set's correction left.
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

// The rounds (already corrected: F_b − A_yᵀΛ_b, F_y − A_yᵀΛ_y) get the
// proximal weights D: F_y ← F_y + D. U, R: the fast path's factors of the
// correction (Q = −F₀ + U·R), or null.
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

// The rounds from the fast path's Phase 1, factored or explicit, corrected
// for constraints on y when E (start_correction).
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

// The rounds on `threads` threads over block ranges (AlternatingOptions::
// threads); y is updated in place, z is left to the caller.
AlternatingSummary run_parallel(const FusedModel& M, FusedWorkspace& W, InputProjection<double>& projection,
                                const AlternatingOptions& options, const detail::StopTest& stop, Index threads,
                                Index block, Eigen::Ref<Vector<double>> y) {
  const Index q = M.q(), blocks = q / block, mu = M.rounds().scratch_size();
  const bool use_float = options.float_products;
  W.y2.resize(q, 2);
  W.y2.col(0) = y;
  // Float rounds: whether the first round moves the reference (every thread
  // then takes the same decision after each barrier, from the same sums).
  const bool first_at_reference = use_float && !near_reference(W, y.data(), q, kNoChange);
  if (use_float) {
    W.yf2.resize(q, 2);
    W.yf2.col(0) = W.yf;
  }
  // Per-thread Σ‖Δy_j‖², ‖y_j‖² and ‖y_j − y_r,j‖², by round parity: read
  // after the round's barrier, next written two rounds later (after the next barrier).
  constexpr int kMaxThreads = 64;
  threads = std::min<Index>(threads, kMaxThreads);
  double change2[2][kMaxThreads] = {}, norm2[2][kMaxThreads] = {}, drift2[2][kMaxThreads] = {};
  // Thread 0's reading of the budget, by round parity like the sums, so that
  // every thread takes the same decision.
  bool spent[2] = {false, false};
  W.scratch_threads.resize(mu, threads);  // these allocate on the first call only
  W.scratch_f_threads.resize(mu, threads);
  AlternatingSummary summary;
#pragma omp parallel num_threads(static_cast<int>(threads))
  {
    const Index t = omp_get_thread_num(), nt = omp_get_num_threads();
    const Index r0 = block * (blocks * t / nt), r1 = block * (blocks * (t + 1) / nt), rows = r1 - r0;
    double* scratch = W.scratch_threads.col(t).data();
    float* scratch_f = W.scratch_f_threads.col(t).data();
    bool at_reference = first_at_reference;
    for (int it = 0; it < options.iterations; ++it) {
      const int cur = it % 2, next = 1 - cur;
      if (!use_float) {
        double_product(M, W, W.y2.col(cur).data(), r0, r1, scratch);
      } else if (at_reference) {  // this thread's rows of y_r: no other thread reads them this round
        reference_product(M, W, W.y2.col(cur).data(), r0, r1, scratch);
        W.y_ref.segment(r0, rows) = W.y2.col(cur).segment(r0, rows);
      } else {
        difference_product(M, W, W.yf2.col(cur).data(), r0, r1, scratch_f);
      }
      change2[cur][t] = projection.project_blocks(W.g, y, r0 / block, r1 / block);
      norm2[cur][t] = static_cast<double>(y.segment(r0, rows).squaredNorm());
      W.y2.col(next).segment(r0, rows) = y.segment(r0, rows);
      if (use_float) {
        drift2[cur][t] = (y.segment(r0, rows) - W.y_ref.segment(r0, rows)).squaredNorm();
        W.yf2.col(next).segment(r0, rows) = (y.segment(r0, rows) - W.y_ref.segment(r0, rows)).cast<float>();
      }
      if (t == 0) spent[cur] = stop.over_budget();
#pragma omp barrier
      // Only this round's sums are read here: y itself may already be
      // changing in another thread's next round.
      double total = 0.0, ynorm2 = 0.0, drift = 0.0;
      for (Index s = 0; s < nt; ++s) {
        total += change2[cur][s];
        ynorm2 += norm2[cur][s];
        drift += drift2[cur][s];
      }
      const double change = std::sqrt(total);
      at_reference = reference_stale(drift, ynorm2, change);
      if (t == 0) {
        summary.iterations = it + 1;
        summary.last_change = change;
      }
      // Every thread takes the same decision from the same sums.
      if (stop.converged(change, std::sqrt(ynorm2))) {
        if (t == 0) summary.stop = RoundStop::Tolerance;
        break;
      }
      if (spent[cur]) {
        if (t == 0) summary.stop = RoundStop::TimeBudget;
        break;
      }
    }
  }
  if (use_float) W.ref_valid = true;
  return summary;
}

// The energy (*) of alternating.h at y, with g = g(y) in W.g:
// ½yᵀN_S y − ½gᵀy − ½(b − A_y·y)ᵀ(λ_b + Λ_y·y), and a bound on its round-off
// (`slack`, relative to the terms' sizes: 1e-9 with float rounds, whose
// products are relative to a double reference, 1e-11 in double).
// With the rounds corrected for constraints on y (proximal weights D, one
// per entry, g′ = g − A_yᵀλ + D∘y in W.g): ½yᵀN_S y − ½g′ᵀy + ½yᵀDy − ½bᵀλ,
// the same value. The constraint term is then bᵀλ = bᵀλ_b + (Λ_yᵀb)ᵀy, as
// it is when A_y = 0: affine in y, c₀ + cᵀy from constraint_term's c₀, c
// (O(k) a round instead of the 2m × k product).
double reduced_energy(const detail::PhaseOneEnergy& E, FusedWorkspace& W, const InputProjection<double>& projection,
                      const Eigen::Ref<const Vector<double>>& b, const Eigen::Ref<const Vector<double>>& y,
                      bool float_rounds, const Vector<double>* D, double* slack) {
  const bool corrected = D != nullptr;
  double constraint = 0.0;
  if (W.constraint_affine) {
    constraint = W.blb + W.lyb.dot(y);
  } else {
    const Index m = E.Lb.rows();
    detail::gemv(E.AyLy, y.data(), W.ay_ly.data(), false);  // [A_y·y; Λ_y·y]
    for (Index i = 0; i < m; ++i) {
      const double lambda = W.lambda_b(i) + W.ay_ly(m + i);
      constraint += (corrected ? b(i) : b(i) - W.ay_ly(i)) * lambda;
    }
  }
  const double quadratic = projection.quadratic_term(y), linear = W.g.dot(y);
  const double proximal = corrected ? y.dot(D->cwiseProduct(y)) : 0.0;
  *slack = (float_rounds ? 1e-9 : 1e-11) *
           (std::abs(quadratic) + std::abs(linear) + std::abs(constraint) + std::abs(proximal));
  return quadratic - 0.5 * linear + 0.5 * proximal - 0.5 * constraint;
}

// Λ_b·b for reduced_energy, and its constraint term's c₀ = bᵀλ_b, c = Λ_yᵀb
// when that term is affine in y (`corrected` rounds, or A_y = 0).
void constraint_term(const detail::PhaseOneEnergy& E, const Eigen::Ref<const Vector<double>>& b, bool corrected,
                     FusedWorkspace& W) {
  const Index m = E.Lb.rows();
  detail::gemv(E.Lb, b.data(), W.lambda_b.data(), false);
  W.constraint_affine = corrected || E.ay_zero;
  if (!W.constraint_affine) return;
  W.blb = b.dot(W.lambda_b);
  if (m == 0) {
    W.lyb.setZero();
  } else {
    detail::gemtv(E.AyLy.data() + m, m, E.AyLy.cols(), E.AyLy.outerStride(), b.data(), W.lyb.data());
  }
}

// Accelerated rounds (AlternatingOptions::anderson_window): Anderson on the
// fixed-point map y ← Π(g(y)) with the retraction and the energy safeguard;
// y ends as the plain step from the last accepted iterate.
AlternatingSummary run_accelerated(const FusedModel& M, FusedWorkspace& W, InputProjection<double>& projection,
                                   const detail::PhaseOneEnergy& E, const Eigen::Ref<const Vector<double>>& b,
                                   const AlternatingOptions& options, const detail::StopTest& stop,
                                   Eigen::Ref<Vector<double>> y) {
  AlternatingSummary summary;
  const bool use_float = options.float_products;
  const bool corrected = M.energy != nullptr;
  auto product = [&](const Vector<double>& at) {
    round_product(M, W, at.data(), use_float, summary.iterations == 0 ? kNoChange : summary.last_change);
  };
  constraint_term(E, b, corrected, W);
  W.anderson.restart();
  W.y_try = y;
  W.y_plain = y;
  double accepted = std::numeric_limits<double>::infinity(), slack = 0.0;
  bool extrapolated = false;  // y_try is an extrapolation (else the plain step itself)
  for (int it = 0; it < options.iterations; ++it) {
    product(W.y_try);
    const Vector<double>* D = corrected ? &M.proximal_entries : nullptr;
    double energy = reduced_energy(E, W, projection, b, W.y_try, use_float, D, &slack);
    if (extrapolated && !(energy <= accepted + slack)) {  // the safeguard: back to the plain step
      W.y_try = W.y_plain;
      product(W.y_try);
      energy = reduced_energy(E, W, projection, b, W.y_try, use_float, D, &slack);
      W.anderson.restart();
      ++summary.rejected;
    }
    accepted = energy;
    W.y_plain = W.y_try;
    summary.last_change = projection.project(W.g, W.y_plain);
    summary.iterations = it + 1;
    if (stop.done(summary.last_change, [&] { return W.y_try.norm(); }, &summary)) break;
    W.anderson.step(W.y_try, W.y_plain, W.y_next);
    extrapolated = W.anderson.history() > 0;
    if (extrapolated) projection.retract(W.y_next);
    W.y_try.swap(W.y_next);
  }
  y = W.y_plain;
  summary.energy = accepted;
  return summary;
}

// Second-order steps for stiff constraints on rotation blocks
// (AlternatingOptions::second_order; alternating.h, "Constraints on y"): a
// Riemannian Newton step with Levenberg–Marquardt damping on E(y) over
// SO(3)^d, y_a ← y_a·exp([ω_a]×). E is quadratic in y with Hessian N_S + Q
// (Q = −(F_y′ − D), explicit), N_S is constant on rotations, so along
// y_a(ω) = S_a·exp([ω]×):
//     E ≈ E(y) + Σ_a gω_a·ω_a + ½ωᵀ(TᵀQT + diag(tr(M_a)·I − sym M_a))ω,
// with c = g′ − D∘y (the corrected input without the damping), M_a = S_aᵀc_a,
// gω_a = −(M₃₂ − M₂₃, M₁₃ − M₃₁, M₂₁ − M₁₂) and T_a (9 × 3) the columns
// vec(S_a·[e_i]×). A step is kept only when (*) does not rise; a rejected one
// raises the damping μ. O(k²·d + d³) per step (a dozen rounds' work); it
// reaches in a few steps what damped rounds need thousands of rounds for.
AlternatingSummary run_second_order(const FusedModel& M, FusedWorkspace& W, InputProjection<double>& projection,
                                    const detail::PhaseOneEnergy& E, const Eigen::Ref<const Vector<double>>& b,
                                    const AlternatingOptions& options, const detail::StopTest& stop,
                                    Eigen::Ref<Vector<double>> y) {
  const Index k = M.k(), d = k / 9;
  const MatD& F = M.explicit_rounds.F;  // F_y − A_yᵀΛ_y + D
  const Vector<double>& D = M.proximal_entries;
  constraint_term(E, b, true, W);
  double slack = 0.0;
  auto evaluate = [&](const Vector<double>& at) {  // W.g ← g′(at); returns (*)
    double_product(M, W, at.data(), 0, k, W.scratch.data());
    return reduced_energy(E, W, projection, b, at, false, &D, &slack);
  };
  AlternatingSummary summary;
  summary.second_order = true;
  W.y_try = y;
  double energy = evaluate(W.y_try);
  // μ is set from the Hessian's scale at the first step: the largest
  // ‖H_aa‖_F, which a rotation of the scene (H_aa ↦ G·H_aa·Gᵀ) keeps, so that
  // the damping, and with it the steps, do not depend on the axes.
  double mu = -1.0, scale = 0.0;
  bool hessian_current = false;
  for (int it = 0; it < options.iterations; ++it) {
    summary.iterations = it + 1;
    W.c = W.g - D.cwiseProduct(W.y_try);
    for (Index a = 0; a < d; ++a) {
      const Eigen::Map<const Eigen::Matrix3d> S(W.y_try.data() + 9 * a), C(W.c.data() + 9 * a);
      const Eigen::Matrix3d Ma = S.transpose() * C;
      W.grad.segment<3>(3 * a) = -Eigen::Vector3d(Ma(2, 1) - Ma(1, 2), Ma(0, 2) - Ma(2, 0), Ma(1, 0) - Ma(0, 1));
      if (!hessian_current) W.curvature[static_cast<size_t>(a)] = Ma.trace() * Eigen::Matrix3d::Identity() -
                                                                   0.5 * (Ma + Ma.transpose());
    }
    if (!hessian_current) {
      for (Index a = 0; a < d; ++a) {
        const Eigen::Map<const Eigen::Matrix3d> S(W.y_try.data() + 9 * a);
        for (int i = 0; i < 3; ++i) {
          Eigen::Matrix3d Ei = Eigen::Matrix3d::Zero();  // [e_i]×
          Ei((i + 2) % 3, (i + 1) % 3) = 1.0;
          Ei((i + 1) % 3, (i + 2) % 3) = -1.0;
          Eigen::Map<Eigen::Matrix3d>(W.T.col(3 * a + i).data()) = S * Ei;
        }
        W.QT.middleCols(3 * a, 3).noalias() = -F.middleCols(9 * a, 9) * W.T.middleCols(3 * a, 3);
        W.QT.block(9 * a, 3 * a, 9, 3) += D.segment(9 * a, 9).asDiagonal() * W.T.middleCols(3 * a, 3);
      }
      for (Index a = 0; a < d; ++a)
        W.H.middleRows(3 * a, 3).noalias() = W.T.middleCols(3 * a, 3).transpose() * W.QT.middleRows(9 * a, 9);
      W.Hmu = W.H.transpose();  // symmetrise without a temporary (run does not allocate)
      W.H += W.Hmu;
      W.H *= 0.5;
      for (Index a = 0; a < d; ++a) W.H.block<3, 3>(3 * a, 3 * a) += W.curvature[static_cast<size_t>(a)];
      hessian_current = true;
      if (mu < 0.0) {
        for (Index a = 0; a < d; ++a) scale = std::max(scale, W.H.block<3, 3>(3 * a, 3 * a).norm());
        scale = std::max(scale, 1e-300);
        mu = 1e-6 * scale;
      }
    }
    const double gnorm = W.grad.norm();
    if (!(gnorm > 0.0)) {  // stationary to the last bit
      summary.stop = RoundStop::Tolerance;
      break;
    }
    // (H + μI)ω = −grad, with μ raised until the system is positive definite.
    for (int tries = 0;; ++tries) {
      W.Hmu = W.H;
      W.Hmu.diagonal().array() += mu;
      W.ldlt.compute(W.Hmu);
      if (W.ldlt.info() == Eigen::Success && W.ldlt.isPositive() && (W.ldlt.vectorD().array() > 0.0).all()) break;
      mu = std::max(4.0 * mu, 1e-12 * scale);
      if (tries > 60) return summary;  // cannot happen for finite H; keeps y
    }
    W.omega = W.ldlt.solve(-W.grad);
    W.y_next = W.y_try;
    for (Index a = 0; a < d; ++a) {
      const Eigen::Vector3d w = W.omega.segment<3>(3 * a);
      const double angle = w.norm();
      if (angle == 0.0) continue;
      Eigen::Map<Eigen::Matrix3d> S(W.y_next.data() + 9 * a);
      S = (S * Eigen::AngleAxisd(angle, w / angle).toRotationMatrix()).eval();
    }
    W.g_keep = W.g;
    const double next = evaluate(W.y_next);
    if (std::isfinite(next) && next <= energy + slack) {
      summary.last_change = (W.y_next - W.y_try).norm();
      W.y_try.swap(W.y_next);
      energy = next;
      mu = std::max(mu / 3.0, 1e-15 * scale);
      hessian_current = false;
      if (stop.done(summary.last_change, [&] { return W.y_try.norm(); }, &summary)) break;
    } else {
      summary.last_change = (W.y_next - W.y_try).norm();  // the step tried: a stalled run does not claim 0
      W.g.swap(W.g_keep);  // g′ of the kept y
      mu *= 4.0;
      ++summary.rejected;
      if (stop.spent(&summary)) break;
    }
  }
  y = W.y_try;
  summary.energy = energy;
  return summary;
}

// The serial rounds.
AlternatingSummary run_serial(const FusedModel& M, FusedWorkspace& W, InputProjection<double>& projection,
                              const AlternatingOptions& options, const detail::StopTest& stop,
                              Eigen::Ref<Vector<double>> y) {
  AlternatingSummary summary;
  for (int it = 0; it < options.iterations; ++it) {
    round_product(M, W, y.data(), options.float_products, it == 0 ? kNoChange : summary.last_change);
    summary.last_change = projection.project(W.g, y);
    summary.iterations = it + 1;
    if (stop.done(summary.last_change, [&] { return static_cast<double>(y.norm()); }, &summary)) break;
  }
  return summary;
}

// Checks what accelerated rounds need and sizes their vectors (allocates
// only when the sizes or the window change). Throws std::invalid_argument.
void prepare_acceleration(const FixedCoordinateSolver<double>& phase1, const InputProjection<double>& projection,
                          const AlternatingOptions& options, const Eigen::Ref<const Vector<double>>& y,
                          FusedWorkspace& W) {
  if (!phase1.has_energy_terms()) {
    throw std::invalid_argument(
        "FusedAlternation::run: accelerated rounds (anderson_window > 0) need the energy terms of Phase 1 "
        "(FixedCoordinateSolver::form_energy_terms after set_constraints)");
  }
  if (!std::isfinite(projection.quadratic_term(y))) {
    throw std::invalid_argument(
        "FusedAlternation::run: this projection cannot be accelerated (its quadratic_term is not given)");
  }
  const Index k = y.size(), m = phase1.m();
  if (W.anderson.size() != k || W.anderson_window != options.anderson_window) {
    W.anderson.reset(k, AndersonOptions{options.anderson_window});
    W.anderson_window = options.anderson_window;
  }
  W.y_try.resize(k);
  W.y_plain.resize(k);
  W.y_next.resize(k);
  W.ay_ly.resize(2 * m);
  W.lambda_b.resize(m);
  W.lyb.resize(k);
}

// Sizes the second-order steps' workspace (allocates only when k changes).
void prepare_second_order(const FixedCoordinateSolver<double>& phase1, Index k, FusedWorkspace& W) {
  const Index d = k / 9, t = 3 * d, m = phase1.m();
  if (W.H.rows() != t) {
    W.c.resize(k);
    W.grad.resize(t);
    W.omega.resize(t);
    W.T.resize(9, t);
    W.QT.resize(k, t);
    W.H.resize(t, t);
    W.Hmu.resize(t, t);
    // (W.ldlt allocates on its first compute() and reuses that storage; it is
    // not assigned a sized LDLT here: Eigen's LDLT(Index) leaves its info
    // uninitialised, and the move would read it, which UBSan reports.)
    W.curvature.resize(static_cast<size_t>(d));
  }
  W.y_try.resize(k);
  W.y_next.resize(k);
  W.g_keep.resize(k);
  W.ay_ly.resize(2 * m);
  W.lambda_b.resize(m);
  W.lyb.resize(k);
}

}  // namespace

template <typename Scalar>
FusedAlternation<Scalar>::FusedAlternation()
    : model_(std::make_unique<FusedModel>()), workspace_(std::make_unique<FusedWorkspace>()) {}

template <typename Scalar>
FusedAlternation<Scalar>::~FusedAlternation() = default;

template <typename Scalar>
FusedAlternation<Scalar>::FusedAlternation(const FusedAlternation& other)
    : model_(std::make_unique<FusedModel>(*other.model_)),
      workspace_(std::make_unique<FusedWorkspace>(*other.workspace_)) {}

template <typename Scalar>
FusedAlternation<Scalar>& FusedAlternation<Scalar>::operator=(const FusedAlternation& other) {
  if (this != &other) {
    *model_ = *other.model_;
    *workspace_ = *other.workspace_;
  }
  return *this;
}

// Moves swap, so that a moved-from object stays usable (and empty of nothing
// it did not have).
template <typename Scalar>
FusedAlternation<Scalar>::FusedAlternation(FusedAlternation&& other) noexcept
    : model_(std::make_unique<FusedModel>()), workspace_(std::make_unique<FusedWorkspace>()) {
  model_.swap(other.model_);
  workspace_.swap(other.workspace_);
}

template <typename Scalar>
FusedAlternation<Scalar>& FusedAlternation<Scalar>::operator=(FusedAlternation&& other) noexcept {
  model_.swap(other.model_);
  workspace_.swap(other.workspace_);
  return *this;
}

template <typename Scalar>
bool FusedAlternation<Scalar>::ready() const {
  return model_->ready;
}

template <typename Scalar>
bool FusedAlternation<Scalar>::factored() const {
  return model_->factored;
}

template <typename Scalar>
bool FusedAlternation<Scalar>::constrained_y() const {
  return model_->energy != nullptr;
}

template <typename Scalar>
bool FusedAlternation<Scalar>::second_order(const InputProjection<Scalar>& projection,
                                            const AlternatingOptions& options) const {
  return model_->second_order && options.second_order && projection.rotation_blocks();
}

template <typename Scalar>
const Vector<double>& FusedAlternation<Scalar>::proximal_weights() const {
  return model_->proximal;
}

template <typename Scalar>
void FusedAlternation<Scalar>::set_proximal_block_size(Index block) {
  if (block < 0) throw std::invalid_argument(fmt::format("FusedAlternation: proximal block size {} < 0", block));
  model_->block = block;
  model_->ready = false;
}

template <typename Scalar>
bool FusedAlternation<Scalar>::float_set() const {
  return model_->float_set;
}

template <typename Scalar>
void FusedAlternation<Scalar>::set(const FixedCoordinateSolver<Scalar>& phase1, const Matrix<Scalar>& Gz,
                                   const Matrix<Scalar>& Gy, int threads, FusedForm form, FusedPrecision precision) {
  set_impl(phase1, &Gz, &Gy, threads, form, precision);
}

template <typename Scalar>
void FusedAlternation<Scalar>::set(const FixedCoordinateSolver<Scalar>& phase1, int threads, FusedForm form,
                                   FusedPrecision precision) {
  if (!model_->inputs_ready) throw std::invalid_argument("FusedAlternation::set: no G_z, G_y given yet");
  set_impl(phase1, nullptr, nullptr, threads, form, precision);
}

// Gz, Gy: new inputs, or null for the kept ones (no comparison, no copy).
template <typename Scalar>
void FusedAlternation<Scalar>::set_impl(const FixedCoordinateSolver<Scalar>& phase1, const Matrix<Scalar>* Gz,
                                        const Matrix<Scalar>* Gy, int threads, FusedForm form,
                                        FusedPrecision precision) {
  FusedModel& M = *model_;
  std::optional<detail::ScopedBlasThreads> blas;  // single-threaded BLAS unless asked (see ConstraintOptions)
  if (threads > 0) blas.emplace(threads);
  if (!phase1.ready()) throw std::invalid_argument("FusedAlternation::set: Phase 1 has no constraints yet");
  const MatD& gz = Gz ? *Gz : M.Gz;
  const MatD& gy = Gy ? *Gy : M.Gy;
  check_size("FusedAlternation::set: G_z columns (d)", phase1.d(), gz.cols());
  check_size("FusedAlternation::set: G_y columns (k)", phase1.k(), gy.cols());
  check_size("FusedAlternation::set: G_y rows (as G_z)", gz.rows(), gy.rows());
  M.ready = false;
  M.factored = false;
  M.float_set = false;
  if (Gz) keep_inputs(M, *Gz, *Gy);
  const detail::PhaseOneEnergy* E = start_correction(M, phase1);
  const detail::FactoredPhaseOne* fast = phase1.phase_one_operator()->factored();
  if (fast) {
    form_c0(M, phase1.preparation(), M.Gz);
    const bool factored =
        form == FusedForm::Factored || (form == FusedForm::Automatic && M.Gz.rows() * M.Gy.cols() > kExplicitMaxEntries);
    set_fast_rounds(M, *fast, E, factored, precision);
  } else {
    set_explicit_plain(M, phase1, M.Gz, M.Gy, E);
    if (E) finish_correction(M, nullptr, nullptr);
  }
  // A stiff set takes second-order steps (run_second_order), which read the
  // explicit double F_y: an Automatic set that came out factored but stiff
  // is set again in the explicit form (once per set, O(q·k·μ)), up to
  // kSecondOrderMaxBlocks blocks (a step factors a 3d × 3d matrix).
  if (M.factored && fast != nullptr && form == FusedForm::Automatic && M.k() / 9 <= kSecondOrderMaxBlocks &&
      stiff_rotation_set(M)) {
    set_fast_rounds(M, *fast, start_correction(M, phase1), false, FusedPrecision::Double);
  }
  size_workspace(M, *workspace_);
  M.ready = true;
}

template <typename Scalar>
void FusedAlternation<Scalar>::prepare(const FixedCoordinateSolver<Scalar>& phase1, const Matrix<Scalar>& Gz,
                                       const Matrix<Scalar>& Gy, FusedPrecision precision) {
  check_size("FusedAlternation::prepare: G_y rows (as G_z)", Gz.rows(), Gy.rows());
  const auto& prep = phase1.preparation();
  if (prep) {
    check_size("FusedAlternation::prepare: G_z columns (d)", prep->G.rows(), Gz.cols());
    check_size("FusedAlternation::prepare: G_y columns (k)", prep->G.cols(), Gy.cols());
  }
  check_finite("FusedAlternation::prepare: G_z", Gz);
  check_finite("FusedAlternation::prepare: G_y", Gy);
  FusedModel& M = *model_;
  M.ready = false;
  keep_inputs(M, Gz, Gy);
  if (prep) {
    const detail::ScopedBlasThreads blas(1);
    form_c0(M, prep, M.Gz);
    if (precision == FusedPrecision::Float) form_gz_float(M, M.Gz);
    if (M.Gz.rows() * M.Gy.cols() > kExplicitMaxEntries) form_factored_base(M);
    if (M.Gy.rows() == M.Gy.cols()) form_curvature_test(M);
  }
}

template <typename Scalar>
AlternatingSummary FusedAlternation<Scalar>::run(const FixedCoordinateSolver<Scalar>& phase1,
                                                 InputProjection<Scalar>& projection,
                                                 const Eigen::Ref<const Vector<Scalar>>& b,
                                                 const AlternatingOptions& options, Eigen::Ref<Vector<Scalar>> z,
                                                 Eigen::Ref<Vector<Scalar>> y) {
  const FusedModel& M = *model_;
  FusedWorkspace& W = *workspace_;
  if (!M.ready) throw std::invalid_argument("FusedAlternation::run: not set (call set after set_constraints or prepare)");
  check_size("FusedAlternation::run: b (m)", M.Fb.cols(), b.size());
  check_size("FusedAlternation::run: y (k)", M.k(), y.size());
  check_size("FusedAlternation::run: z (d)", phase1.d(), z.size());
  assert(options.is_valid(nullptr));
  if (M.float_set && !options.float_products) {
    throw std::invalid_argument(
        "FusedAlternation::run: set with FusedPrecision::Float needs float rounds "
        "(AlternatingOptions::float_products)");
  }
  if (M.energy_seen != phase1.shared_energy_terms()) {
    throw std::invalid_argument(
        "FusedAlternation::run: Phase 1's energy terms changed after `set` (form_energy_terms before set, which "
        "reads them for constraints on y)");
  }
  if (M.energy && projection.proximal_block_size() != M.block) {
    throw std::invalid_argument(fmt::format(
        "FusedAlternation::run: the projection's proximal blocks ({}) are not those the rounds were set for ({}; "
        "set_proximal_block_size before set)",
        projection.proximal_block_size(), M.block));
  }
  projection.set_proximal_weights(M.proximal);
  const detail::StopTest stop(options);  // the budget counts from here
  // The products go through the run-time dispatched AVX2/FMA kernels
  // (simd_kernels.h) when the CPU has them.
  detail::gemv(M.Fb, b.data(), W.gb.data(), false);
  const Index q = M.q(), k = M.k(), block = projection.block_size();
  const int threads = options.threads > 0 ? options.threads : omp_get_max_threads();
  const bool parallel = threads > 1 && block > 0 && !omp_in_parallel() && q == k && q % block == 0 &&
                        q * k >= options.parallel_min_entries && q / block >= 2;
  AlternatingSummary summary;
  if (second_order(projection, options)) {
    prepare_second_order(phase1, k, W);
    summary = run_second_order(M, W, projection, *phase1.energy_terms(), b, options, stop, y);
  } else if (options.anderson_window > 0) {
    prepare_acceleration(phase1, projection, options, y, W);
    summary = run_accelerated(M, W, projection, *phase1.energy_terms(), b, options, stop, y);
  } else {
    summary = parallel ? run_parallel(M, W, projection, options, stop, std::min<Index>(threads, q / block), block, y)
                       : run_serial(M, W, projection, options, stop, y);
  }
  phase1.solve(b, y, z);
  summary.status = Status::Success;
  return summary;
}

template class FusedAlternation<double>;

}  // namespace qpreduce
