#include "validators.h"

#include <fmt/format.h>

#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <string>

namespace qpr {

namespace {

// A token shown in a message: at most this many characters of it.
constexpr std::size_t kShownChars = 40;

std::string shown(const std::string& s) {
  return s.size() <= kShownChars ? "'" + s + "'"
                                 : fmt::format("'{}…' ({} characters)", s.substr(0, kShownChars), s.size());
}

// "" and the value when `s` is one finite number and nothing else; else the message.
std::string parse_finite(const std::string& s, double* value) {
  errno = 0;
  char* end = nullptr;
  *value = std::strtod(s.c_str(), &end);
  if (s.empty() || end == s.c_str() || *end != '\0') return "expected a number, got " + shown(s);
  if (std::isnan(*value)) return "must be a number, got NaN";
  if (std::isinf(*value)) return "must be finite, got " + shown(s);
  return "";
}

// The range in interval notation, shown in --help after the option's type
// ("FLOAT:[0, 1]"), which tests/apps/option_ranges.py reads.
std::string interval(double lo, double hi, bool open_below) {
  const auto bound = [](double v) { return std::isinf(v) ? std::string(v < 0 ? "-inf" : "inf") : fmt::format("{:g}", v); };
  return fmt::format("{}{}, {}{}", open_below || std::isinf(lo) ? "(" : "[", bound(lo), bound(hi),
                     std::isinf(hi) ? ")" : "]");
}

CLI::Validator number_check(const std::string& description, double lo, double hi, bool open_below) {
  return CLI::Validator(
      [=](std::string& s) -> std::string {
        double v = 0.0;
        const std::string problem = parse_finite(s, &v);
        if (!problem.empty()) return problem;
        const bool below = open_below ? !(v > lo) : !(v >= lo);
        if (below || !(v <= hi)) return fmt::format("must be {}, got {}", description, shown(s));
        return "";
      },
      interval(lo, hi, open_below));
}

}  // namespace

CLI::Validator number_between(double lo, double hi) {
  return number_check(fmt::format("between {:g} and {:g}", lo, hi), lo, hi, false);
}

CLI::Validator number_at_least(double lo) {
  return number_check(fmt::format("at least {:g}", lo), lo, HUGE_VAL, false);
}

CLI::Validator number_above(double lo, double hi) {
  const std::string upper = std::isinf(hi) ? "" : fmt::format(" and at most {:g}", hi);
  return number_check(fmt::format("greater than {:g}{}", lo, upper), lo, hi, true);
}

CLI::Validator whole_number_between(long long lo, long long hi) {
  return CLI::Validator(
      [=](std::string& s) -> std::string {
        const std::string rule = fmt::format("must be a whole number from {} to {}", lo, hi);
        errno = 0;
        char* end = nullptr;
        const long long v = std::strtoll(s.c_str(), &end, 10);
        if (s.empty() || end == s.c_str() || *end != '\0') return rule + ", got " + shown(s);
        if (errno == ERANGE || v < lo || v > hi) return rule + ", got " + shown(s);
        return "";
      },
      fmt::format("[{}, {}]", lo, hi));
}

CLI::Validator unsigned_whole_number() {
  return CLI::Validator(
      [](std::string& s) -> std::string {
        const std::string rule = "must be a whole number from 0 to 18446744073709551615";
        if (s.empty() || s.find_first_not_of("0123456789") != std::string::npos) return rule + ", got " + shown(s);
        errno = 0;
        (void)std::strtoull(s.c_str(), nullptr, 10);
        if (errno == ERANGE) return rule + ", got " + shown(s);
        return "";
      },
      "[0, 18446744073709551615]");
}

}  // namespace qpr
