// A test helper: the soft file-size limit (RLIMIT_FSIZE) lowered for a scope,
// with SIGXFSZ ignored so that an oversized write() fails with EFBIG ("File
// too large") instead of the signal ending the test. Restores both on exit.
#pragma once

#include <csignal>

#include <sys/resource.h>

namespace qpreduce_test {

class FileSizeLimit {
 public:
  explicit FileSizeLimit(rlim_t bytes) {
    old_handler_ = std::signal(SIGXFSZ, SIG_IGN);
    getrlimit(RLIMIT_FSIZE, &old_);
    rlimit r = old_;
    r.rlim_cur = bytes;
    setrlimit(RLIMIT_FSIZE, &r);
  }
  ~FileSizeLimit() {
    setrlimit(RLIMIT_FSIZE, &old_);
    std::signal(SIGXFSZ, old_handler_);
  }
  FileSizeLimit(const FileSizeLimit&) = delete;
  FileSizeLimit& operator=(const FileSizeLimit&) = delete;

 private:
  rlimit old_{};
  void (*old_handler_)(int) = nullptr;
};

}  // namespace qpreduce_test
