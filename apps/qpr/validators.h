// qpr — option checks whose messages state the rule in words
// ("--trials: must be at least 1, got 0"), for every numeric option.
//
// Unlike CLI11's Range / PositiveNumber they refuse NaN and infinities, text
// after the number ("3x"), a minus sign on an unsigned option (CLI11 would
// wrap "-1" to 2⁶⁴−1), and print their bounds briefly (%g, not 309 digits).
#pragma once

#include <CLI/CLI.hpp>
#include <cmath>

namespace qpr {

// The largest penalty weight (--alpha, --beta, --gamma) accepted: past it
// the assembled energy's entries leave the range in which its Cholesky
// factorization keeps any significant digit, or overflow outright.
constexpr double kMaxPenalty = 1e12;

// A finite number x with lo ≤ x ≤ hi ("must be between 0 and 1").
CLI::Validator number_between(double lo, double hi);
// A finite number x ≥ lo ("must be at least 0").
CLI::Validator number_at_least(double lo);
// A finite number x > lo, and x ≤ hi when hi is finite ("must be greater than 0").
CLI::Validator number_above(double lo, double hi = HUGE_VAL);
// A whole number n with lo ≤ n ≤ hi ("must be a whole number from 1 to 1000").
CLI::Validator whole_number_between(long long lo, long long hi);
// A whole number ≥ 0 of any size up to 2⁶⁴−1 (seeds), digits only.
CLI::Validator unsigned_whole_number();

}  // namespace qpr
