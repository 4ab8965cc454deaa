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

#include "qpreduce/util/file_error.h"

#include <string>
#include <utility>

namespace qpreduce::deform {

// what() is "<file>:<line>: <problem>", or "<file>: <problem>" when line is 0
// (binary data, whole-file checks); see qpreduce::FileError.
class IoError : public FileError {
 public:
  IoError(std::string file, long line, std::string problem)
      : FileError(std::move(file), line, std::move(problem)) {}
};

}  // namespace qpreduce::deform
