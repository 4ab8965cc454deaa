// A summary's fields; see report.h.
#include "qpreduce/report.h"

#include <fmt/format.h>

namespace qpreduce {

const Report::Value* Report::find(const std::string& key) const {
  for (const Entry& e : entries_)
    if (e.key == key) return &e.value;
  return nullptr;
}

namespace {

std::string value_text(const Report::Value& v, int indent) {
  struct Visitor {
    int indent;
    std::string operator()(bool b) const { return b ? "true" : "false"; }
    std::string operator()(long long i) const { return std::to_string(i); }
    std::string operator()(double x) const { return fmt::format("{:.6g}", x); }
    std::string operator()(const std::string& s) const { return s; }
    std::string operator()(const std::vector<double>& xs) const {
      std::string out = fmt::format("{} values", xs.size());
      for (size_t i = 0; i < xs.size() && i < 4; ++i) out += fmt::format("{}{:.6g}", i == 0 ? ": " : ", ", xs[i]);
      return xs.size() > 4 ? out + ", …" : out;
    }
    std::string operator()(const std::shared_ptr<const Report>& r) const { return "\n" + r->text(indent + 2); }
  };
  return std::visit(Visitor{indent}, v);
}

}  // namespace

std::string Report::text(int indent) const {
  std::string out;
  const std::string pad(static_cast<size_t>(indent), ' ');
  for (const Entry& e : entries_) {
    const bool nested = std::holds_alternative<std::shared_ptr<const Report>>(e.value);
    out += pad + e.key + ":" + (nested ? "" : " ") + value_text(e.value, indent) + (nested ? "" : "\n");
  }
  return out;
}

}  // namespace qpreduce
