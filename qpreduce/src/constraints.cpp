// ConstraintOptions and ConstraintSummary (constraints.h).
#include "qpreduce/constraints.h"

#include <cmath>

namespace qpreduce {

bool ConstraintOptions::is_valid(std::string* why) const {
  auto fail = [why](const char* msg) {
    if (why) *why = msg;
    return false;
  };
  if (soft && !(delta > 0.0 && std::isfinite(delta))) return fail("delta must be positive and finite");
  if (!(rank_tolerance > 0.0 && rank_tolerance < 1.0)) return fail("rank_tolerance must lie in (0, 1)");
  if (threads < 0) return fail("threads must be non-negative");
  if (!(drop_tolerance >= 0.0 && drop_tolerance < 1.0)) return fail("drop_tolerance must lie in [0, 1)");
  if (!(factored_cost_ratio > 0.0 && std::isfinite(factored_cost_ratio)))
    return fail("factored_cost_ratio must be positive and finite");
  return true;
}

void ConstraintSummary::add_details(Report* out) const {
  out->add("m", m)
      .add("rank", rank)
      .add("condition", condition)
      .add("fast_path", fast_path)
      .add("factored", factored)
      .add("dropped", dropped)
      .add("beyond_subspace", beyond_subspace)
      .add("seconds", seconds);
}

}  // namespace qpreduce
