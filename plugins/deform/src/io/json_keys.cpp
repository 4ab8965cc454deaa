// Duplicate JSON keys, found by a SAX pass; see json_keys.h.
#include "qpreduce/deform/io/json_keys.h"

#include <nlohmann/json.hpp>

#include <fmt/format.h>

#include <cstddef>
#include <set>
#include <vector>

namespace qpreduce::deform {

namespace {

using json = nlohmann::json;

// Tracks the open objects (their keys so far) and arrays (their next index).
class KeyChecker : public nlohmann::json_sax<json> {
 public:
  explicit KeyChecker(const std::string& file) : file_(file) {}

  bool null() override { return value(); }
  bool boolean(bool) override { return value(); }
  bool number_integer(number_integer_t) override { return value(); }
  bool number_unsigned(number_unsigned_t) override { return value(); }
  bool number_float(number_float_t, const string_t&) override { return value(); }
  bool string(string_t&) override { return value(); }
  bool binary(binary_t&) override { return value(); }
  bool start_object(std::size_t) override {
    value();
    open_.push_back(Level{true, {}, "", 0});
    return true;
  }
  bool key(string_t& k) override {
    Level& level = open_.back();
    if (!level.keys.insert(k).second) throw IoError(file_, 0, fmt::format("{}: duplicate key '{}'", pointer(), k));
    level.key = k;
    return true;
  }
  bool end_object() override {
    open_.pop_back();
    return true;
  }
  bool start_array(std::size_t) override {
    value();
    open_.push_back(Level{false, {}, "", -1});
    return true;
  }
  bool end_array() override {
    open_.pop_back();
    return true;
  }
  bool parse_error(std::size_t, const std::string&, const nlohmann::detail::exception&) override { return false; }

 private:
  struct Level {
    bool object;
    std::set<std::string> keys;
    std::string key;  // objects: the current key
    long index;       // arrays: the current element
  };
  // A value starts: in an array, it is the next element.
  bool value() {
    if (!open_.empty() && !open_.back().object) ++open_.back().index;
    return true;
  }
  // The JSON pointer of the innermost open object (without its current key).
  std::string pointer() const {
    std::string p;
    for (std::size_t i = 0; i + 1 < open_.size(); ++i)
      p += "/" + (open_[i].object ? open_[i].key : std::to_string(open_[i].index));
    return p.empty() ? "/" : p;
  }

  std::string file_;
  std::vector<Level> open_;
};

}  // namespace

void check_unique_json_keys(std::string_view text, const std::string& file) {
  KeyChecker checker(file);
  json::sax_parse(text.begin(), text.end(), &checker, nlohmann::detail::input_format_t::json, false);
}

}  // namespace qpreduce::deform
