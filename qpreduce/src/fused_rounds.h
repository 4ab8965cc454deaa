// Private to the engine: FusedAlternation's model and workspace (alternation_parts.h;
// derivation in docs/engine.md, "The alternation").
//
// A round forms g = g_b + F_y·y (q entries, g_b = F_b·b once per run) and
// projects it. F_y (q × k) comes in one of two forms behind RoundOperator:
//
//   ExplicitRounds  F_y as a matrix (and its float copy);
//   FactoredRounds  F₀ = C0 + G_y (q × k, kept while Phase 1's preparation,
//                   G_z and G_y stay the same) and, per constraint set,
//                   U (q × μ) and R (μ × k, kept as Rᵀ): F_y·y = F₀·y − U·(R·y), with
//                   U = G_z·T, or G_z·T + A_yᵀ·K when the rounds correct for
//                   constraints on y (fused_form.cpp, form_u).
#pragma once

#include "phase_one.h"
#include "simd_kernels.h"

#include "qpreduce/anderson.h"
#include "qpreduce/common.h"

#include <Eigen/Cholesky>

#include <algorithm>
#include <memory>
#include <vector>

namespace qpreduce::detail {

class RoundOperator {
 public:
  virtual ~RoundOperator() = default;
  // out[r0, r1) += rows [r0, r1) of F_y·y, in double or in float. scratch:
  // scratch_size() entries. No heap allocation.
  virtual void add_rows(const double* y, Index r0, Index r1, double* scratch, double* out) const = 0;
  virtual void add_rows(const float* y, Index r0, Index r1, float* scratch, float* out) const = 0;
  virtual Index scratch_size() const = 0;
};

class ExplicitRounds final : public RoundOperator {
 public:
  Matrix<double> F;    // F_y (q × k)
  Matrix<float> F_f;   // F_y in float

  void add_rows(const double* y, Index r0, Index r1, double* /*scratch*/, double* out) const override {
    gemv_add(F.data() + r0, r1 - r0, F.cols(), F.outerStride(), y, out + r0);
  }
  void add_rows(const float* y, Index r0, Index r1, float* /*scratch*/, float* out) const override {
    gemv_add(F_f.data() + r0, r1 - r0, F_f.cols(), F_f.outerStride(), y, out + r0);
  }
  Index scratch_size() const override { return 0; }
};

class FactoredRounds final : public RoundOperator {
 public:
  Matrix<double> F0;                // C0 + G_y (q × k)
  Matrix<float> F0_f;               // in float
  bool base_valid = false;          // F0 is current for (C0, G_y)
  bool symmetric = false;           // F0 symmetric to CurvatureTest::kSymmetry: whole products read its lower triangle
  Matrix<double> U, Rt;             // U (q × μ; U_f in double after a Float set), Rᵀ (k × μ: R·y as μ dot products)
  Matrix<float> U_f, Rt_f;          // in float
  Vector<double> shift;             // diag(D)·y added to the rows (q = k; constraints on y), or empty

  void add_rows(const double* y, Index r0, Index r1, double* scratch, double* out) const override {
    add_rows_of(F0, U, Rt, y, r0, r1, scratch, out);
  }
  void add_rows(const float* y, Index r0, Index r1, float* scratch, float* out) const override {
    add_rows_of(F0_f, U_f, Rt_f, y, r0, r1, scratch, out);
  }
  Index scratch_size() const override { return Rt.cols(); }

 private:
  // out += F0·y − U·(R·y) + shift∘y on rows [r0, r1); scratch = −R·y (μ).
  // All rows of a symmetric F0: its lower triangle only (half the bytes of a
  // product that streams F0 from the caches).
  template <typename T>
  void add_rows_of(const Matrix<T>& F0, const Matrix<T>& U, const Matrix<T>& Rt, const T* y, Index r0, Index r1,
                   T* scratch, T* out) const {
    const Index rows = r1 - r0, mu = Rt.cols();
    if (symmetric && r0 == 0 && r1 == F0.rows())
      symv_lower_add(F0, y, out);
    else
      gemv_add(F0.data() + r0, rows, F0.cols(), F0.outerStride(), y, out + r0);
    gemtv(Rt.data(), Rt.rows(), mu, Rt.outerStride(), y, scratch);
    for (Index i = 0; i < mu; ++i) scratch[i] = -scratch[i];
    gemv_add(U.data() + r0, rows, mu, U.outerStride(), scratch, out + r0);
    if (shift.size() > 0)
      for (Index r = r0; r < r1; ++r) out[r] += static_cast<T>(shift[r]) * y[r];
  }
};

// Whether the corrected rounds need proximal weights at all (alternation_parts.h,
// "Constraints on y"): D = 0 exactly when Q ⪯ 0. On the fast path
// Q = −F₀ + U·R with F₀ = C0 + G_y the same for every constraint set and
// U·R = Q + F₀ symmetric, of rank ≤ μ (U = G_z·T + A_yᵀ·K, q × μ; R μ × k).
// With R̂ (r × k) an orthonormal basis of R's rows, U·R = R̂ᵀ·M·R̂ with
// M = R̂·U·R·R̂ᵀ symmetric (r × r), and with F₀ + εI = L·Lᵀ positive definite
// (formed once per F₀), W = R̂·(F₀ + εI)⁻¹·R̂ᵀ = L_W·L_Wᵀ:
//     λ_max(Q) ≤ ε  ⟺  L⁻¹·R̂ᵀ·M·R̂·L⁻ᵀ ⪯ I  ⟺  λ_max(L_Wᵀ·M·L_W) ≤ 1
// (the nonzero eigenvalues of X·M·Xᵀ, X = L⁻¹·R̂ᵀ, are those of M·XᵀX). One
// triangular solve with μ right-hand sides, O(q²·μ/2), and μ × μ algebra
// per set, where a Lanczos run for λ_max(Q) needs hundreds of products with
// Q when Q's top eigenvalues are clustered (they are on the Table 1 models:
// Q's top is F₀'s bottom, where the handles barely reach). When F₀ + εI is
// not positive definite, F₀ not symmetric, or U·R not of that form, the
// test does not apply and the Lanczos run decides.
struct CurvatureTest {
  // ε = kFloor·‖F₀‖_F: Q is formed in double from sums of at most q ≤ 10³
  // products, so a λ_max(Q) this small is round-off (a structurally zero
  // one, a direction the handles leave free, comes out ±10⁻¹⁶‖F₀‖), and
  // weights of that size would change the rounds by nothing but the switch
  // to second-order steps, thrown by chance.
  static constexpr double kFloor = 1e-10;
  // F₀ is symmetric to round-off (measured ‖F₀ − F₀ᵀ‖_F ≤ 10⁻¹³‖F₀‖_F on
  // the Table 1 models); a larger asymmetry means a Q of another kind.
  static constexpr double kSymmetry = 1e-9;
  // U = R̂ᵀ·R̂·U and M = Mᵀ to kFactorFit (relative, Frobenius): a Float
  // set's U carries float round-off (6·10⁻⁸ of an entry; measured misfits
  // 2–6·10⁻⁷ on the Table 1 models, 10⁻¹³ in double), a U·R of another
  // form misses by the order of U itself.
  static constexpr double kFactorFit = 1e-5;
  // R's rows are taken as independent down to this fraction of λ_max(R·Rᵀ)
  // (round-off of R·Rᵀ in double; the lifted rows LᵀG can be zero).
  static constexpr double kRowRank = 1e-13;
  Matrix<double> factor;  // L of F₀ + εI = LLᵀ in the lower triangle (q × q), or empty: no test
  double floor = 0.0;     // ε
  bool formed = false;    // for the current F₀
  bool usable() const { return formed && factor.size() > 0; }
};

// What FusedAlternation::set and prepare form.
struct FusedModel {
  // The last inputs (q × d, q × k), for set(phase1) and the bitwise tests.
  Matrix<double> Gz, Gy;
  bool inputs_ready = false;
  // C0 = G_z·P0 (q × k) for Phase 1's preparation `prep`, and G_z in float
  // (formed at the first Float set; emptied whenever C0 is redone).
  std::shared_ptr<const FixedCoordinatePrep> prep;
  Matrix<double> C0;
  Matrix<float> Gz_f;
  // The curvature test for F₀ = C0 + G_y (q = k), formed with C0 or lazily.
  CurvatureTest curvature;
  // The current constraint set.
  Matrix<double> Fb;  // F_b = G_z·M_b (q × m)
  ExplicitRounds explicit_rounds;
  FactoredRounds factored_rounds;
  bool factored = false;   // the rounds use factored_rounds
  bool float_set = false;  // factored_rounds.U_f and Fb were formed in float
  bool ready = false;
  // Constraints on y (docs/engine.md, "Constraints on y"): the energy terms
  // the rounds were corrected with (null: not corrected), and the proximal
  // weights D (one per block of `block` entries; empty when not corrected).
  // In the explicit form D sits on F_y's diagonal; in the factored form G_z·T
  // and R carry A_yᵀ and Λ_y as m more columns and rows, and D is `shift`.
  std::shared_ptr<const PhaseOneEnergy> energy;
  Index block = 0;          // the projection's proximal_block_size (0: one scalar weight)
  Vector<double> proximal;  // D per block
  Vector<double> proximal_entries;  // D per entry of y (k), for ‖y‖²_D
  bool second_order = false;        // stiff set: second-order steps available (run_second_order)
  // Phase 1's energy terms when `set` ran (corrected or not), so that `run`
  // can tell when they changed after it.
  std::shared_ptr<const PhaseOneEnergy> energy_seen;

  const RoundOperator& rounds() const {
    return factored ? static_cast<const RoundOperator&>(factored_rounds) : explicit_rounds;
  }
  Index q() const { return Fb.rows(); }
  Index k() const { return Gy.cols(); }
};

// The rounds' vectors (allocated by `set`, reused by every `run`).
struct FusedWorkspace {
  Vector<double> gb, g;                // F_b·b and g (q)
  Vector<float> gf, yf;                // float rounds: F_y·(y − y_r) (q) and y − y_r (k)
  // Float rounds' double reference (round_product.h, kReferenceDrift):
  // y_r (k) and F_y·y_r (q), valid until the next `set`.
  Vector<double> y_ref, Fy_ref, dy;  // dy: y − y_r (k)
  bool ref_valid = false;
  Vector<double> scratch;              // μ, the factored form's R·y
  Vector<float> scratch_f;
  Matrix<double> scratch_threads;      // μ × threads (parallel rounds)
  Matrix<float> scratch_f_threads;
  // Parallel rounds: y as read by the next round's product, double-buffered
  // (round r reads column r mod 2 and its Phase 2 writes the other).
  Matrix<double> y2;
  Matrix<float> yf2;
  // Accelerated rounds: the iterate tried, the plain step from the last
  // accepted one, the extrapolation (k each); [A_y·y; Λ_y·y] (2m), Λ_b·b (m);
  // the energy's constraint term when affine in y, c₀ + cᵀy (c = Λ_yᵀb, k).
  SafeguardedAnderson anderson;
  Vector<double> y_try, y_plain, y_next, ay_ly, lambda_b, lyb;
  double blb = 0.0;
  bool constraint_affine = false;
  // Second-order steps: c = g′ − D∘y (k), the gradient and step in the
  // tangent coordinates ω (3d), T (9 × 3d: block a's tangent basis in
  // columns 3a..3a+2), Q·T (k × 3d), the model Hessian and its damped copy
  // (3d × 3d), the blocks' curvature terms, g′ of the kept y.
  Vector<double> c, grad, omega, g_keep;
  Matrix<double> T, QT, H, Hmu;
  Eigen::LDLT<Matrix<double>> ldlt;
  std::vector<Eigen::Matrix3d> curvature;
};

}  // namespace qpreduce::detail
