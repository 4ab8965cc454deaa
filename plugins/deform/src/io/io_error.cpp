// IoError is compiled into qpreduce::deform (not deform_io): the deformer's
// cache throws it too.
#include "qpreduce/deform/io/io_error.h"

#include <fmt/format.h>

#include <utility>

namespace qpreduce::deform {

namespace {
std::string compose(const std::string& file, long line, const std::string& problem) {
  return line > 0 ? fmt::format("{}:{}: {}", file, line, problem) : fmt::format("{}: {}", file, problem);
}
}  // namespace

IoError::IoError(std::string file, long line, std::string problem)
    : std::runtime_error(compose(file, line, problem)),
      file_(std::move(file)),
      line_(line),
      problem_(std::move(problem)) {}

}  // namespace qpreduce::deform
