// qpreduce — what one Alternation (alternation.h) is told and tells: the
// settings of a run (AlternationSettings), what `setup` builds for one
// constraint set (AlternationSetup, FusedForm, FusedPrecision) and what a
// run reports (AlternationResults, RoundStop), as ProxSuite's settings and
// results.
#pragma once

#include "qpreduce/common.h"
#include "qpreduce/constraints.h"

#include <limits>
#include <string>

namespace qpreduce {

// Why a run's rounds ended (AlternationResults::stop).
enum class RoundStop {
  RoundLimit,  // AlternationSettings::iterations rounds ran
  Tolerance,   // the last round's ‖Δy‖ met AlternationSettings::tolerance
  TimeBudget,  // AlternationSettings::time_budget was spent first
};
const char* to_string(RoundStop stop);  // "round limit", "tolerance", "time budget"

// How one run goes (they may change between runs of one setup).
struct AlternationSettings {
  // Rounds per run: the cap with `tolerance` or `time_budget`, the count
  // without them (the paper's fixed 8 per frame). ≥ 1.
  int iterations = 8;
  // Stop early when ‖Δy‖ ≤ tolerance·max(1, ‖y‖). 0: always run `iterations`.
  double tolerance = 0.0;
  // Stop once the rounds have run this many seconds (checked after each
  // round or second-order step: the first always runs, the last may end past
  // the budget by one). 0: no budget. Finite and ≥ 0.
  double time_budget = 0.0;
  // The clock the budget reads, in seconds from any origin; nullptr:
  // std::chrono::steady_clock. For tests and simulations.
  double (*clock)() = nullptr;
  // The round's product in float relative to a double reference y_r,
  // g = F_b·b + F_y·y_r + F_y·(y − y_r): the rounds reach the fixed points of
  // double rounds; Phase 1's final z stays in double. Required after a setup
  // with FusedPrecision::Float.
  bool float_products = false;
  // OpenMP threads for the rounds when the projection is block-separable
  // (InputProjection::block_size() > 0) and F_y has at least
  // parallel_min_entries entries (0 threads: omp_get_max_threads()). The
  // iterates are the serial ones up to the last bits of an entry of g.
  int threads = 1;
  Index parallel_min_entries = 256 * 256;
  // Anderson acceleration (anderson.h) of the fixed-point map with the
  // retraction and the energy safeguard (an extrapolation that raises E(y)
  // is replaced by the plain step). 0: plain rounds; else 1–16. Needs a
  // setup that formed the energy terms (Alternation::energy_terms()).
  int anderson_window = 0;
  // Stiff constraints on rotation blocks (Alternation::second_order): damped
  // Riemannian Newton steps on E(y) instead of rounds, `iterations` of them.
  bool second_order = true;

  // False with a reason, e.g. "iterations must be at least 1, got 0".
  bool is_valid(std::string* why) const;
};

struct AlternationResults : Outcome {  // Success after a run
  int iterations = 0;                   // rounds (or second-order steps) run
  RoundStop stop = RoundStop::RoundLimit;
  double last_change = 0.0;  // ‖Δy‖ of the last Phase 2
  // Accelerated rounds and second-order steps: E(y) of the last accepted y
  // (up to the float rounds' round-off), and the extrapolations refused.
  double energy = std::numeric_limits<double>::quiet_NaN();
  int rejected = 0;
  bool second_order = false;  // second-order steps ran
};

// How the model keeps F_y = G_z·(M_Y + M_b·T) + G_y when Phase 1 came from
// its fast path: Explicit forms the q × k matrix per constraint set;
// Factored keeps the part common to every set and applies a rank-(m + ν)
// correction each round (O(q·μ·d) per set instead of O(q·μ·k)). Automatic:
// Factored for q·k > Alternation::kExplicitMaxEntries.
enum class FusedForm { Automatic, Explicit, Factored };

// The precision of the factored form's per-set product (most of a set's
// cost): Float runs it at about twice the BLAS rate, for runs with
// AlternationSettings::float_products (a Float set's fixed point is that of
// the rounded operator; Phase 1's z stays in double).
enum class FusedPrecision { Double, Float };

// What `setup` builds for one constraint set.
struct AlternationSetup {
  // Hard or soft constraints, tolerances, the fast path, and the BLAS
  // threads of the setup's products (ConstraintOptions::threads).
  ConstraintOptions constraints;
  // T (m × k): the constraints' right-hand side is b + T·y (empty: b). With
  // T, E(y) is not formed (plain rounds only).
  SparseMatrix<double> follow_y;
  // Form Phase 1's energy terms E(y) where they apply (hard or soft
  // constraints solved without a least-squares fallback, no T, a projection
  // with quadratic_term): accelerated rounds need them, and constraints on y
  // (A_y ≠ 0) step on E(y) with them. false: plain rounds.
  bool energy_terms = true;
  FusedForm form = FusedForm::Automatic;
  FusedPrecision precision = FusedPrecision::Double;
};

}  // namespace qpreduce
