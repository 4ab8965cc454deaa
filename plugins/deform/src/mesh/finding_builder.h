// The pre-flight's findings, collected one offender at a time
// (mesh_check.cpp, orientation checks). Internal to the mesh check.
#pragma once

#include "qpreduce/deform/mesh/mesh_check.h"

#include <fmt/format.h>

#include <string>
#include <utility>
#include <vector>

namespace qpreduce::deform {

// 1234567 as "1,234,567".
inline std::string grouped(Index value) {
  std::string digits = std::to_string(value < 0 ? -value : value), out;
  for (size_t i = 0; i < digits.size(); ++i) {
    if (i > 0 && (digits.size() - i) % 3 == 0) out += ',';
    out += digits[i];
  }
  return value < 0 ? "-" + out : out;
}

inline std::string plural(const std::string& item) { return item == "vertex" ? "vertices" : item + "s"; }

// Collects the offenders of one defect; finish() writes the message from the
// first offender's sentence and the count.
class FindingBuilder {
 public:
  FindingBuilder(MeshDefect defect, CheckSeverity severity, std::string item, Index max_listed)
      : max_listed_(max_listed) {
    f_.defect = defect;
    f_.severity = severity;
    f_.item = std::move(item);
  }
  // Returns true for the first offender (whose sentence the caller then sets).
  bool add(std::vector<Index> offender) {
    if (static_cast<Index>(f_.first.size()) < max_listed_) f_.first.push_back(std::move(offender));
    return f_.count++ == 0;
  }
  void sentence(std::string s) { sentence_ = std::move(s); }
  Index count() const { return f_.count; }
  // Sets the count when it is not the number of offenders added (the
  // orientation check lists a few of the triangles it counts).
  void set_count(Index count) { f_.count = count; }
  // Appends the finding to `out` when there was an offender.
  void finish(std::vector<MeshFinding>* out) {
    if (f_.count == 0) return;
    f_.message = sentence_;
    if (f_.count > 1) f_.message += fmt::format(" ({} {} in all)", grouped(f_.count), plural(f_.item));
    out->push_back(std::move(f_));
  }

 private:
  MeshFinding f_;
  Index max_listed_;
  std::string sentence_;
};

}  // namespace qpreduce::deform
