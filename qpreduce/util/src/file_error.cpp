// The base of file errors; see file_error.h.
#include "qpreduce/util/file_error.h"

#include <fmt/format.h>

#include <utility>

namespace qpreduce {

namespace {
std::string file_error_message(const std::string& file, long line, const std::string& problem) {
  return line > 0 ? fmt::format("{}:{}: {}", file, line, problem) : fmt::format("{}: {}", file, problem);
}
}  // namespace

FileError::FileError(std::string file, long line, std::string problem)
    : std::runtime_error(file_error_message(file, line, problem)),
      file_(std::move(file)),
      line_(line),
      problem_(std::move(problem)) {}

}  // namespace qpreduce
