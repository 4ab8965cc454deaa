// Private to the engine: Phase 1 of the alternation (alternation.h) for one
// constraint set, z = M_b·b + M_Y·Y (b: m, Y: k, z: d), in one of two forms
// behind one small interface (the derivation: docs/engine.md, "The
// alternation"):
//
//   ExplicitPhaseOne   M_b (d × m) and M_Y (d × k) as matrices (the
//                      null-space method, src/qp_operators.h);
//   FactoredPhaseOne   the range-space fast path on H_zz: M_b = T's first m
//                      columns and M_Y = P0 − T·R, with T = Y'·Σ⁻¹ (d × μ),
//                      R = [A_z·P0 + A_y; LᵀG] (μ × k), μ = m + ν, and P0 the
//                      per-solver part (FixedCoordinatePrep). Its multipliers
//                      (range_space.h, with g = G·y, c = b − A_y·y) are
//                      λ = K·(R·y − [b; 0]), K = Σ⁻¹'s first m rows (m × μ):
//                      Λ_y = K·R and Λ_b = −K's first m columns.
//
// Both are immutable once made, so FixedCoordinateSolver copies share them.
#pragma once

#include "qpreduce/common.h"
#include "range_space.h"
#include "simd_kernels.h"

#include <cstdint>
#include <memory>
#include <optional>
#include <vector>

namespace qpreduce::detail {

// The fast path's per-solver part, once per SubspaceSolver::generation():
// with G = NᵀD − H_zy (d × k) the unconstrained z-response to Y is P0 = M0·G.
struct FixedCoordinatePrep {
  std::uint64_t generation = 0;  // SubspaceSolver::generation() it was made from
  RangeSpace range;              // of H_zz (d × d)
  Matrix<double> G;              // NᵀD − H_zy (d × k)
  Matrix<double> P0;             // M0·G (d × k)
  Matrix<double> LtG;            // LᵀG (ν × k), L = D_sV_L/σ the lifted directions
};

class FactoredPhaseOne;

// A_z (m × d) as a scaled selection: row i has one nonzero, a_i, in column
// cols[i], and no two rows share a column (so A_z has full row rank m).
struct ScaledSelection {
  std::vector<Index> cols;    // c_i (m)
  Eigen::VectorXd inv_scale;  // 1/a_i (m)
  std::vector<Index> free;    // the other d − m columns, ascending
};

// The selection A_z is, or nullopt (m = 0, a row without or with a second
// nonzero, two rows in one column). O(m·d).
std::optional<ScaledSelection> scaled_selection(const Matrix<double>& Az);

// The terms of the reduced energy of one constraint set
// (FixedCoordinateSolver::form_energy_terms): λ = Λ_b·b + Λ_y·y.
struct PhaseOneEnergy {
  Matrix<double> AyLy;  // [A_y; Λ_y] (2m × k): one product gives A_y·y and Λ_y·y
  Matrix<double> Lb;    // Λ_b (m × m)
  bool ay_zero = true;  // A_y = 0 (or m = 0): the energy's constraint term is affine in y
};

class PhaseOneOperator {
 public:
  virtual ~PhaseOneOperator() = default;
  const Matrix<double>& Mb() const { return Mb_; }  // d × m
  // M_Y (d × k), formed on each call in the factored form.
  virtual Matrix<double> MY() const = 0;
  // z = M_b·b + M_Y·Y. scratch: μ entries (factored form; unused otherwise).
  // No heap allocation.
  virtual void apply(const double* b, const double* Y, double* z, double* scratch) const = 0;
  // The factored form, or null.
  virtual const FactoredPhaseOne* factored() const { return nullptr; }
  // A_z's selection when the operator eliminated it, or null.
  virtual const ScaledSelection* selection() const { return nullptr; }
  virtual Index scratch_size() const { return 0; }

 protected:
  explicit PhaseOneOperator(Matrix<double> Mb) : Mb_(std::move(Mb)) {}
  Matrix<double> Mb_;
};

class ExplicitPhaseOne final : public PhaseOneOperator {
 public:
  ExplicitPhaseOne(Matrix<double> Mb, Matrix<double> MY, std::optional<ScaledSelection> selection = std::nullopt)
      : PhaseOneOperator(std::move(Mb)), MY_(std::move(MY)), selection_(std::move(selection)) {}
  Matrix<double> MY() const override { return MY_; }
  const ScaledSelection* selection() const override { return selection_ ? &*selection_ : nullptr; }
  const Matrix<double>& explicit_MY() const { return MY_; }
  void apply(const double* b, const double* Y, double* z, double* /*scratch*/) const override {
    gemv(Mb_, b, z, false);
    gemv(MY_, Y, z, true);
  }

 private:
  Matrix<double> MY_;  // d × k
  std::optional<ScaledSelection> selection_;
};

class FactoredPhaseOne final : public PhaseOneOperator {
 public:
  // T: d × μ with M_b its first m columns; R: μ × k; K: m × μ.
  FactoredPhaseOne(std::shared_ptr<const FixedCoordinatePrep> prep, Matrix<double> T, Matrix<double> R,
                   Matrix<double> K)
      : PhaseOneOperator(T.leftCols(K.rows())),
        prep_(std::move(prep)),
        T_(std::move(T)),
        R_(std::move(R)),
        K_(std::move(K)) {}
  Matrix<double> MY() const override;
  void apply(const double* b, const double* Y, double* z, double* scratch) const override;
  const FactoredPhaseOne* factored() const override { return this; }
  Index scratch_size() const override { return R_.rows(); }

  const FixedCoordinatePrep& prep() const { return *prep_; }
  const Matrix<double>& T() const { return T_; }  // d × μ
  const Matrix<double>& R() const { return R_; }  // μ × k
  const Matrix<double>& K() const { return K_; }  // m × μ: λ = K·(R·y − [b; 0])

 private:
  std::shared_ptr<const FixedCoordinatePrep> prep_;
  Matrix<double> T_;
  Matrix<double> R_;
  Matrix<double> K_;
};

// Phase 1 by elimination, for hard constraints whose A_z is the scaled
// selection `sel`: with C = sel.cols and F = sel.free (f = d − m),
//     z_C = diag(1/a)·(b − A_y·Y),   z_F = H_FF⁻¹·(G_F·Y − H_FC·z_C),
// so M_b and M_Y are X = [X_C; X_F] with X_C = diag(1/a)·[I, −A_y] and
// X_F = H_FF⁻¹·([0, G_F] − H_FC·X_C). O(f³/3 + f²·(m + k) + f·m·k).
// Hzz: H_zz (d × d); G: NᵀD − H_zy (d × k); Ay: m × k. Null when H_FF is
// not clearly positive definite (a Cholesky of the Jacobi-scaled H_FF whose
// pivot ratio times options.rank_tolerance stays below 10⁻², the null-space
// method's test): the minimiser is then not unique or near it, and the
// null-space method decides. Sets *summary (Success, rank m, the
// selection's condition max|a|/min|a|) when it returns an operator.
std::shared_ptr<const PhaseOneOperator> eliminated_phase_one(const Matrix<double>& Hzz, const Matrix<double>& G,
                                                             const Matrix<double>& Ay, ScaledSelection sel,
                                                             const ConstraintOptions& options,
                                                             ConstraintSummary* summary);

// Whether the elimination costs fewer multiply-adds than the range-space
// fast path for m hard rows on d linear and k rotational coordinates
// (prepared: the fast path's per-solver part is already made).
bool elimination_pays(Index d, Index m, Index k, bool prepared);

}  // namespace qpreduce::detail
