// Wall-clock timer for summaries (not for benchmarks: those use Google Benchmark).
#pragma once

#include <chrono>

namespace qpreduce::detail {

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

}  // namespace qpreduce::detail
