#include "blas_memory.h"

#include <qpreduce/util/cpu_features.h>

#include <fmt/format.h>

#include <dlfcn.h>
#include <omp.h>
#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <cstdio>
#include <stdexcept>
#include <vector>

namespace qpr {

namespace {

constexpr double kMiB = 1024.0 * 1024.0;
// OpenBLAS's BUFFER_SIZE (128 MiB) and page; glibc reserves a 64 MiB heap
// for the arena of each new thread that allocates; a margin for the rest of
// the run's start.
constexpr double kBufferBytes = 128.0 * kMiB + 8192.0;
constexpr double kArenaBytes = 64.0 * kMiB;
constexpr double kMarginBytes = 32.0 * kMiB;

double address_space_in_use() {
  std::FILE* f = std::fopen("/proc/self/statm", "r");
  long pages = 0;
  if (f == nullptr) return 0.0;
  if (std::fscanf(f, "%ld", &pages) != 1) pages = 0;
  std::fclose(f);
  return static_cast<double>(pages) * static_cast<double>(sysconf(_SC_PAGESIZE));
}

using Dgemm = void (*)(const char*, const char*, const int*, const int*, const int*, const double*, const double*,
                       const int*, const double*, const int*, const double*, double*, const int*);

}  // namespace

bool single_threaded_blas_under_limit(char** argv) {
  rlimit limit{};
  if (getrlimit(RLIMIT_AS, &limit) != 0 || limit.rlim_cur == RLIM_INFINITY) return false;
  if (std::getenv("OPENBLAS_NUM_THREADS") != nullptr) return false;
  setenv("OPENBLAS_NUM_THREADS", "1", 1);
  // Every thread that calls BLAS at the same time takes a buffer of its own
  // (the engine's blocked solves call CHOLMOD from each OpenMP thread): one
  // thread too, unless the user chose.
  setenv("OMP_NUM_THREADS", "1", 0);
  qpreduce::prefer_blas_core();  // one restart for both (cpu_features.h)
  execv("/proc/self/exe", argv);
  std::fprintf(stderr,
               "qpr: error: cannot restart with OPENBLAS_NUM_THREADS=1 under the address-space limit "
               "(ulimit -v): %s; set OPENBLAS_NUM_THREADS yourself\n",
               std::strerror(errno));
  return true;
}

void reserve_blas_buffers() {
  rlimit limit{};
  if (getrlimit(RLIMIT_AS, &limit) != 0 || limit.rlim_cur == RLIM_INFINITY) return;
  // OpenBLAS's own dgemm_ (another BLAS loaded first may export one too).
  void* threads_symbol = dlsym(RTLD_DEFAULT, "openblas_get_num_threads");
  Dl_info library{};
  if (threads_symbol == nullptr || dladdr(threads_symbol, &library) == 0) return;  // not OpenBLAS
  void* openblas = dlopen(library.dli_fname, RTLD_LAZY | RTLD_NOLOAD);
  if (openblas == nullptr) return;
  const auto threads_of = reinterpret_cast<int (*)()>(threads_symbol);
  const auto dgemm = reinterpret_cast<Dgemm>(dlsym(openblas, "dgemm_"));
  dlclose(openblas);  // still loaded (the process links it)
  if (dgemm == nullptr) return;
  // Buffers held at once: OpenBLAS's threads for one call, times the OpenMP
  // threads that may call it together.
  const int callers = std::max(1, omp_get_max_threads());
  const int threads = std::max(1, threads_of()) * callers;
  const double cap = static_cast<double>(limit.rlim_cur);
  const double needed = threads * kBufferBytes + (threads - 1) * kArenaBytes + kMarginBytes;
  const double free_bytes = cap - address_space_in_use();
  if (free_bytes < needed) {
    const double one_thread = kBufferBytes + kMarginBytes;
    throw std::runtime_error(fmt::format(
        "out of memory: the address-space limit (ulimit -v) of {:.0f} MB leaves {:.0f} MB free, and the linear "
        "algebra's work buffers (OpenBLAS, {} at once) need {:.0f} MB; raise the limit by {:.0f} MB{}",
        cap / kMiB, std::max(0.0, free_bytes) / kMiB, threads, needed / kMiB, (needed - free_bytes) / kMiB,
        threads > 1 && free_bytes >= one_thread ? " or run with OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1" : ""));
  }
  // A product on every calling thread at once, each long enough (about 30 ms)
  // that they overlap: each takes a buffer, which OpenBLAS keeps for the run.
  const int n = 384;
  const double one = 1.0, zero = 0.0;
  const std::vector<double> a(static_cast<size_t>(n) * n, 1.0);
#pragma omp parallel num_threads(callers)
  {
    std::vector<double> c(static_cast<size_t>(n) * n, 0.0);
#pragma omp barrier
    dgemm("N", "N", &n, &n, &n, &one, a.data(), &n, a.data(), &n, &zero, c.data(), &n);
  }
}

}  // namespace qpr
