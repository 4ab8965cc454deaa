// Private to the engine: the factored fast path of SubspaceSolver (the math:
// docs/engine.md, "Factored fast path"). All in unscaled
// coordinates, double; p: subspace size, ν: lifted directions, k: columns of
// D, m: constraints, q = m + ν.
#pragma once

#include "qpreduce/common.h"

#include <Eigen/SparseCore>

namespace qpreduce::detail {

struct RangeSpace;  // src/range_space.h (T₂, T₃ and ‖H̃⁻¹‖_F² come from there)

// The operators of one constraint set.
struct FactoredOperators {
  Matrix<double> Y;       // [M0·A_rᵀ, L] (p × q)
  Matrix<double> Sinv;    // Σ⁻¹ (q × q, symmetric, both triangles)
  Matrix<double> PhiNeg;  // −Σ⁻¹·YᵀBᵀD (q × k)
};

// At = A_rᵀ (p × m, sparse: only its nonzeros are touched). c = 1/(2δ) for
// soft constraints, 0 for hard ones (then A_r must have full row rank: the
// caller's rank test). true: *out holds the operators and the fast path's
// acceptance test, λ_up·‖M̄_q‖_F < 1/rank_tolerance with λ_up = σ (hard) or
// σ + 2δ‖Ā‖_F² (soft), passed. false: a Cholesky factor of Σ failed, the
// test failed, or a value is not finite; *out is unspecified.
// rs: prepared with factored_terms; P0 = M0·BᵀD (p × k), lift_btd = LᵀBᵀD
// (ν × k).
bool factored_operators(const RangeSpace& rs, const Matrix<double>& P0, const Matrix<double>& lift_btd,
                        const Eigen::SparseMatrix<double>& At, bool soft, double delta, double rank_tolerance,
                        double abar_squared_norm, FactoredOperators* out);

}  // namespace qpreduce::detail
