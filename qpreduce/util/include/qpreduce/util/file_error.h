// qpreduce — the base of every file error, by a reader or a writer.
#pragma once

#include <stdexcept>
#include <string>

namespace qpreduce {

// An error found in a file: what() is "<file>:<line>: <problem>", or
// "<file>: <problem>" when line is 0 (a problem not tied to one line: cannot
// open the file, binary data, whole-file checks). The readers' exceptions
// derive from it (MatrixMarketError, deform::IoError), so a caller may catch
// either the specific type or this.
class FileError : public std::runtime_error {
 public:
  FileError(std::string file, long line, std::string problem);

  const std::string& file() const { return file_; }
  long line() const { return line_; }
  const std::string& problem() const { return problem_; }

 private:
  std::string file_;
  long line_;
  std::string problem_;
};

}  // namespace qpreduce
