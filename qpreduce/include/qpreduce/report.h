// qpreduce — a summary's fields as an ordered list of named values: what
// Outcome::report() returns, Outcome::full_report() prints, the apps write
// as JSON and Python returns from to_dict(), so every surface uses the same
// keys (the summary's field names; docs/formats.md, "Summaries").
#pragma once

#include <memory>
#include <string>
#include <type_traits>
#include <utility>
#include <variant>
#include <vector>

namespace qpreduce {

class Report {
 public:
  // A value: a flag, an integer, a real (may be NaN or infinite: the JSON
  // writer gives null), a text, a list of reals, or a nested summary.
  using Value = std::variant<bool, long long, double, std::string, std::vector<double>, std::shared_ptr<const Report>>;
  struct Entry {
    std::string key;
    Value value;
  };

  // Appends `key` with `value`: bool, any integer, float or double, text
  // (std::string, const char*), an enum with a to_string overload (as its
  // name), std::vector<double>, or a Report (nested).
  template <typename T>
  Report& add(std::string key, const T& value) {
    if constexpr (std::is_same_v<T, bool>) {
      entries_.push_back({std::move(key), Value(value)});
    } else if constexpr (std::is_enum_v<T>) {
      entries_.push_back({std::move(key), Value(std::string(to_string(value)))});
    } else if constexpr (std::is_integral_v<T>) {
      entries_.push_back({std::move(key), Value(static_cast<long long>(value))});
    } else if constexpr (std::is_floating_point_v<T>) {
      entries_.push_back({std::move(key), Value(static_cast<double>(value))});
    } else if constexpr (std::is_same_v<T, Report>) {
      entries_.push_back({std::move(key), Value(std::make_shared<const Report>(value))});
    } else if constexpr (std::is_same_v<T, std::vector<double>>) {
      entries_.push_back({std::move(key), Value(value)});
    } else {
      entries_.push_back({std::move(key), Value(std::string(value))});
    }
    return *this;
  }

  const std::vector<Entry>& entries() const { return entries_; }
  // The entry named `key`, or nullptr.
  const Value* find(const std::string& key) const;

  // One "key: value" line per entry, nested reports indented by two spaces
  // a level; reals in %.6g, lists as their length and first values.
  std::string text(int indent = 0) const;

 private:
  std::vector<Entry> entries_;
};

}  // namespace qpreduce
