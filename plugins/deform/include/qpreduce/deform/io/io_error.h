// qpreduce::deform — the exception every reader throws.
//
// A reader never returns partial data: a missing file, a malformed number,
// NaN/inf, an index out of range, a count that disagrees with the header, a
// truncated file, an unsupported variant of a format or an empty mesh all
// throw IoError. Its message names the file, the line for text formats, and
// the problem:
//     "data/bunny.off:17: malformed number '0.3x1' (expected y coordinate)"
//     "data/cylinder.sel: expected 4802 entries (one per mesh vertex), got 4800"
#pragma once

#include <stdexcept>
#include <string>

namespace qpreduce::deform {

class IoError : public std::runtime_error {
 public:
  // line = 0 when the problem has no line (binary data, whole-file checks).
  IoError(std::string file, long line, std::string problem);

  const std::string& file() const { return file_; }
  long line() const { return line_; }
  const std::string& problem() const { return problem_; }

 private:
  std::string file_;
  long line_;
  std::string problem_;
};

}  // namespace qpreduce::deform
