// qpreduce — argument checks, the base of file errors and a wall-clock timer,
// for the engine and for the plugins built on it.
//
// The checks are the API-boundary layer of qpreduce's errors (see common.h):
// each throws std::invalid_argument with a message that starts with `what`.
#pragma once

#include "qpreduce/common.h"

#include <chrono>
#include <stdexcept>
#include <string>

namespace qpreduce {

// Throws std::invalid_argument("<what>: expected <expected>, got <got>") when
// expected != got.
void check_size(const char* what, Index expected, Index got);

// Throws std::invalid_argument("<what>: contains NaN or infinite entries")
// when any (stored) entry of m is NaN or infinite.
template <typename Derived>
void check_finite(const char* what, const Eigen::MatrixBase<Derived>& m) {
  if (!m.allFinite()) {
    throw std::invalid_argument(std::string(what) + ": contains NaN or infinite entries");
  }
}
template <typename Scalar>
void check_finite(const char* what, const SparseMatrix<Scalar>& m) {
  const Eigen::Map<const Vector<Scalar>> values(m.valuePtr(), m.nonZeros());
  if (!values.allFinite()) {
    throw std::invalid_argument(std::string(what) + ": contains NaN or infinite entries");
  }
}

// Throws std::invalid_argument when ‖H − Hᵀ‖_F > tolerance·‖H‖_F.
// H: n by n.
template <typename Scalar>
void check_symmetric(const char* what, const SparseMatrix<Scalar>& H, double tolerance);

// An error found in a file, by a reader or a writer: what() is
// "<file>:<line>: <problem>", or "<file>: <problem>" when line is 0 (a
// problem not tied to one line: cannot open the file, binary data, whole-file
// checks). The readers' exceptions derive from it (MatrixMarketError,
// deform::IoError), so a caller may catch either the specific type or this.
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

// Hands the heap's free memory back to the system (glibc's malloc_trim; a
// no-op elsewhere). glibc keeps freed blocks that lie below live ones, so the
// temporaries of one phase of a large precompute (assembly, symbolic
// analysis) would otherwise stay resident under the next phase's peak.
void release_free_heap();

// Wall-clock seconds for summaries (benchmarks use Google Benchmark instead).
class Timer {
 public:
  Timer() : start_(std::chrono::steady_clock::now()) {}
  void reset() { start_ = std::chrono::steady_clock::now(); }
  double seconds() const {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  }

 private:
  std::chrono::steady_clock::time_point start_;
};

}  // namespace qpreduce
