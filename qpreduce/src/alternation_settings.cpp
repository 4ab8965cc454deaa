// AlternationSettings and RoundStop (alternation_settings.h).
#include "qpreduce/alternation_settings.h"

#include "qpreduce/anderson.h"

#include <fmt/format.h>

#include <cmath>

namespace qpreduce {

bool AlternationSettings::is_valid(std::string* why) const {
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

}  // namespace qpreduce
