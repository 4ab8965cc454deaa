// The one stop test of the alternation's rounds (AlternationSettings:
// iterations, tolerance, time_budget), shared by the plain, parallel,
// accelerated and second-order loops of fused_steps.h.
#pragma once

#include "alternation_parts.h"

#include <algorithm>
#include <chrono>

namespace qpreduce::detail {

class StopTest {
 public:
  // Starts the budget's clock (when there is a budget).
  explicit StopTest(const AlternationSettings& options)
      : tolerance_(options.tolerance), budget_(options.time_budget), clock_(options.clock) {
    if (budget_ > 0.0) start_ = now();
  }

  // ‖Δy‖ = change meets the tolerance at ‖y‖ = ynorm.
  bool converged(double change, double ynorm) const {
    return tolerance_ > 0.0 && change <= tolerance_ * std::max(1.0, ynorm);
  }
  bool over_budget() const { return budget_ > 0.0 && now() - start_ >= budget_; }

  // After a round: true, with summary->stop set, when the rounds end here.
  // ynorm() gives ‖y‖; it is called only when there is a tolerance (O(k)
  // a round that rounds without one need not pay).
  template <typename YNorm>
  bool done(double change, const YNorm& ynorm, AlternationResults* summary) const {
    if (tolerance_ > 0.0 && converged(change, ynorm())) {
      summary->stop = RoundStop::Tolerance;
      return true;
    }
    return spent(summary);
  }
  // After a step that cannot meet the tolerance (a rejected one): the budget only.
  bool spent(AlternationResults* summary) const {
    if (!over_budget()) return false;
    summary->stop = RoundStop::TimeBudget;
    return true;
  }

 private:
  double now() const {
    if (clock_ != nullptr) return clock_();
    return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
  }

  double tolerance_, budget_;
  double (*clock_)();
  double start_ = 0.0;
};

}  // namespace qpreduce::detail
