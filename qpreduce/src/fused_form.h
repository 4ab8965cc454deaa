// Private to the engine: forming the fused rounds' operators once per
// handle set (FusedAlternation::set and prepare, fused_alternation.cpp):
// the explicit or the factored form of F_y, the corrections for
// constraints on y and their proximal weights, and the workspace's sizes.
// `set` calls keep_inputs, start_correction, then set_fast_rounds (fast
// path: form_c0 first) or set_explicit_plain and finish_correction, and
// size_workspace last; `prepare` forms C0, G_z's float copy, F₀ and the
// curvature test ahead of the first set.
#pragma once

#include "fused_rounds.h"
#include "phase_one.h"

#include "alternation_parts.h"

#include <memory>

namespace qpreduce::detail {

// Keeps copies of the inputs; a changed input invalidates what was formed from it.
void keep_inputs(FusedModel& M, const Matrix<double>& Gz, const Matrix<double>& Gy);

// C0 = G_z·P0, once per (Phase 1 preparation, G_z).
void form_c0(FusedModel& M, const std::shared_ptr<const FixedCoordinatePrep>& prep, const Matrix<double>& Gz);

// F₀ = C0 + G_y for the factored rounds (and its float copy), once per (C0, G_y).
void form_factored_base(FusedModel& M);

// The curvature test's factor L, F₀ + εI = LLᵀ (fused_rounds.h,
// CurvatureTest), once per (C0, G_y), for q = k; left empty when F₀ is not
// symmetric or F₀ + εI not positive definite. O(k³).
void form_curvature_test(FusedModel& M);

// G_z's float copy unless it is current (form_c0 empties it).
void form_gz_float(FusedModel& M, const Matrix<double>& Gz);

// Explicit form from Phase 1's null-space method: F_b = G_z·M_b, F_y = G_z·M_Y + G_y,
// then F_b ← F_b − A_yᵀΛ_b, F_y ← F_y − A_yᵀΛ_y when E (constraints on y).
void set_explicit_plain(FusedModel& M, const FixedCoordinateSolver<double>& phase1, const Matrix<double>& Gz,
                        const Matrix<double>& Gy, const PhaseOneEnergy* E);

// Damped rounds (some proximal weight > 0) on blocks of 3 × 3 with q = k:
// the stiff sets that second-order steps are for (once the weights are formed).
bool stiff_rotation_set(const FusedModel& M);

// Constraints on y (alternation.h): the energy terms the rounds correct
// for — Phase 1 has them, A_y ≠ 0 and q = k — or null. Resets what the last
// set's correction left.
const PhaseOneEnergy* start_correction(FusedModel& M, const FixedCoordinateSolver<double>& phase1);

// The rounds (already corrected: F_b − A_yᵀΛ_b, F_y − A_yᵀΛ_y) get the
// proximal weights D: F_y ← F_y + D. U, R: the fast path's factors of the
// correction (Q = −F₀ + U·R), or null.
void finish_correction(FusedModel& M, const Matrix<double>* U, const Matrix<double>* R);

// The rounds from the fast path's Phase 1, factored or explicit, corrected
// for constraints on y when E (start_correction).
void set_fast_rounds(FusedModel& M, const FactoredPhaseOne& fast, const PhaseOneEnergy* E, bool factored,
                     FusedPrecision precision);

// Sizes the rounds' vectors for this model (allocates only when q, k or the
// scratch size change).
void size_workspace(const FusedModel& M, FusedWorkspace& W);

}  // namespace qpreduce::detail
