// Private to the engine: the rounds' product g = g_b + F_y·y (fused_rounds.h),
// in double or as float rounds relative to a double reference, for every
// loop of fused_steps.h.
//
// Float rounds (AlternationSettings::float_products) form
//     g = g_b + F_y·y_r + F_y·(y − y_r)
// with F_y·y_r in double at a reference y_r and only the difference's
// product in float. The reference moves to y (one double product) when
// ‖y − y_r‖ > kReferenceDrift·‖y‖, or > kReferenceStep·‖Δy‖ of the last
// round. The float round-off in g, ~6e-8·‖F_y‖·‖y − y_r‖ (the factored
// form's F₀·y − U·(R·y) is a difference of terms much larger than g), then
// stays under a tenth of a plain float product's and shrinks with the
// steps, so the rounds stop where double rounds stop (a plain float product
// left a residual floor near 1e-7), and Anderson's energy safeguard can take
// a slack of 1e-9 (fused_accelerated_rounds.cpp, reduced_energy; with plain float
// products it needed 1e-6, and accepted rises that added up over hundreds of
// rounds). kReferenceStep: 1e3 moved the reference so often that default
// frames cost 10–25 % more; 1e5 costs what plain float products did
// (docs/engine.md, "Float rounds").
#pragma once

#include "fused_rounds.h"

#include <limits>

namespace qpreduce::detail {

constexpr double kReferenceDrift = 0.1;
constexpr double kReferenceStep = 1e5;
constexpr double kNoChange = std::numeric_limits<double>::infinity();  // before a run's first round

// Whether the reference must move before a float round at ‖y − y_r‖² =
// drift2, ‖y‖² = norm2, after a round of ‖Δy‖ = change.
bool reference_stale(double drift2, double norm2, double change);

// Rows [r0, r1) of g = g_b + F_y·y in double (scratch: scratch_size()).
void double_product(const FusedModel& M, FusedWorkspace& W, const double* y, Index r0, Index r1, double* scratch);

// Rows [r0, r1) of F_y·y into W.Fy_ref and of g: the reference moves to y
// (the caller copies y into W.y_ref).
void reference_product(const FusedModel& M, FusedWorkspace& W, const double* y, Index r0, Index r1, double* scratch);

// Rows [r0, r1) of g from yf = y − y_r in float (W.yf, or a column of W.yf2).
void difference_product(const FusedModel& M, FusedWorkspace& W, const float* yf, Index r0, Index r1, float* scratch_f);

// W.yf = y − y_r in float (k entries); whether a float round may use y_r
// (false when it is stale or not valid).
bool near_reference(FusedWorkspace& W, const double* y, Index k, double change);

// W.g = g_b + F_y·y (all q rows), in double, or as a float round that
// moves the reference when near_reference says so. change: the last
// round's ‖Δy‖ (kNoChange before the first).
void round_product(const FusedModel& M, FusedWorkspace& W, const double* y, bool use_float, double change);

}  // namespace qpreduce::detail
