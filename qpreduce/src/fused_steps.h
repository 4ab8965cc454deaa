// Private to the engine: the loops of FusedAlternation::run
// (fused_alternation.cpp), one file each: plain rounds, serial or on
// threads (fused_plain_rounds.cpp); Anderson-accelerated rounds with their
// energy safeguard (fused_accelerated_rounds.cpp); Riemannian Newton steps
// on stiff rotation sets (fused_second_order.cpp). Each updates y in place
// and leaves z to the caller.
#pragma once

#include "fused_rounds.h"
#include "phase_one.h"
#include "round_stop.h"

#include "alternation_parts.h"

namespace qpreduce::detail {

// The rounds on `threads` threads over block ranges (AlternationSettings::
// threads); y is updated in place, z is left to the caller.
AlternationResults run_parallel(const FusedModel& M, FusedWorkspace& W, InputProjection<double>& projection,
                                const AlternationSettings& options, const StopTest& stop, Index threads, Index block,
                                Eigen::Ref<Vector<double>> y);

// The serial rounds.
AlternationResults run_serial(const FusedModel& M, FusedWorkspace& W, InputProjection<double>& projection,
                              const AlternationSettings& options, const StopTest& stop, Eigen::Ref<Vector<double>> y);

// The energy (*) of alternation_parts.h at y, with g = g(y) in W.g:
// ½yᵀN_S y − ½gᵀy − ½(b − A_y·y)ᵀ(λ_b + Λ_y·y), and a bound on its round-off
// (`slack`, relative to the terms' sizes: 1e-9 with float rounds, whose
// products are relative to a double reference, 1e-11 in double).
// With the rounds corrected for constraints on y (proximal weights D, one
// per entry, g′ = g − A_yᵀλ + D∘y in W.g): ½yᵀN_S y − ½g′ᵀy + ½yᵀDy − ½bᵀλ,
// the same value. The constraint term is then bᵀλ = bᵀλ_b + (Λ_yᵀb)ᵀy, as
// it is when A_y = 0: affine in y, c₀ + cᵀy from constraint_term's c₀, c
// (O(k) a round instead of the 2m × k product).
double reduced_energy(const PhaseOneEnergy& E, FusedWorkspace& W, const InputProjection<double>& projection,
                      const Eigen::Ref<const Vector<double>>& b, const Eigen::Ref<const Vector<double>>& y,
                      bool float_rounds, const Vector<double>* D, double* slack);

// Λ_b·b for reduced_energy, and its constraint term's c₀ = bᵀλ_b, c = Λ_yᵀb
// when that term is affine in y (`corrected` rounds, or A_y = 0).
void constraint_term(const PhaseOneEnergy& E, const Eigen::Ref<const Vector<double>>& b, bool corrected,
                     FusedWorkspace& W);

// Accelerated rounds (AlternationSettings::anderson_window): Anderson on the
// fixed-point map y ← Π(g(y)) with the retraction and the energy safeguard;
// y ends as the plain step from the last accepted iterate.
AlternationResults run_accelerated(const FusedModel& M, FusedWorkspace& W, InputProjection<double>& projection,
                                   const PhaseOneEnergy& E, const Eigen::Ref<const Vector<double>>& b,
                                   const AlternationSettings& options, const StopTest& stop,
                                   Eigen::Ref<Vector<double>> y);

// Checks what accelerated rounds need and sizes their vectors (allocates
// only when the sizes or the window change). Throws std::invalid_argument.
void prepare_acceleration(const FixedCoordinateSolver<double>& phase1, const InputProjection<double>& projection,
                          const AlternationSettings& options, const Eigen::Ref<const Vector<double>>& y,
                          FusedWorkspace& W);

// Sizes the vectors that the accelerated rounds and the second-order steps
// both use (y_try, y_next and reduced_energy's; allocates only when k or m
// change).
void size_energy_workspace(Index k, Index m, FusedWorkspace& W);

// Second-order steps for stiff constraints on rotation blocks
// (AlternationSettings::second_order; docs/engine.md, "Constraints on y"): a
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
AlternationResults run_second_order(const FusedModel& M, FusedWorkspace& W, InputProjection<double>& projection,
                                    const PhaseOneEnergy& E, const Eigen::Ref<const Vector<double>>& b,
                                    const AlternationSettings& options, const StopTest& stop,
                                    Eigen::Ref<Vector<double>> y);

// Sizes the second-order steps' workspace (allocates only when k changes).
void prepare_second_order(const FixedCoordinateSolver<double>& phase1, Index k, FusedWorkspace& W);

}  // namespace qpreduce::detail
