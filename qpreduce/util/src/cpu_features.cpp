// The run-time kernel choices; see cpu_features.h.
#include "qpreduce/util/cpu_features.h"

#include <dlfcn.h>
#include <unistd.h>

#include <cstdlib>
#include <cstring>

namespace qpreduce {

bool cpu_has_avx2_fma() {
  static const bool yes = [] {
    const char* off = std::getenv("QPREDUCE_DISABLE_AVX2");
    if (off != nullptr && std::strcmp(off, "0") != 0) return false;
#if defined(__x86_64__) && defined(__GNUC__)
    return __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
#else
    return false;
#endif
  }();
  return yes;
}

const char* preferred_blas_core() {
#if defined(__x86_64__) && defined(__GNUC__)
  __builtin_cpu_init();  // idempotent: safe however early the caller runs
  if (!__builtin_cpu_is("intel")) return "";
  if (__builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512cd") &&
      __builtin_cpu_supports("avx512bw") && __builtin_cpu_supports("avx512dq") && __builtin_cpu_supports("avx512vl"))
    return "SkylakeX";
  if (__builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma")) return "Haswell";
#endif
  return "";
}

bool prefer_blas_core() {
  const char* core = preferred_blas_core();
  if (*core == '\0' || std::getenv("OPENBLAS_CORETYPE") != nullptr || std::getenv("QPREDUCE_KEEP_BLAS_CORE") != nullptr)
    return false;
  return setenv("OPENBLAS_CORETYPE", core, 0) == 0;
}

std::string blas_core() {
  using CoreName = char* (*)();
  // RTLD_DEFAULT misses an OpenBLAS that a Python module loaded locally.
  void* symbol = dlsym(RTLD_DEFAULT, "openblas_get_corename");
  if (symbol == nullptr) {
    if (void* library = dlopen("libopenblas.so.0", RTLD_LAZY | RTLD_NOLOAD)) {
      symbol = dlsym(library, "openblas_get_corename");
      dlclose(library);  // drops the reference RTLD_NOLOAD took; the library stays
    }
  }
  if (symbol == nullptr) return "";
  const char* name = reinterpret_cast<CoreName>(symbol)();
  return name != nullptr ? std::string(name) : std::string();
}

void restart_with_blas_core(char** argv) {
  if (argv == nullptr || argv[0] == nullptr) return;
  if (std::strcmp(preferred_blas_core(), "") == 0 || blas_core() != "Prescott") return;
  const char* preload = std::getenv("LD_PRELOAD");
  if (preload != nullptr && std::strstr(preload, "vgpreload") != nullptr) return;  // valgrind
  if (!prefer_blas_core()) return;
  execv("/proc/self/exe", argv);
  unsetenv("OPENBLAS_CORETYPE");  // execv failed: go on as we are, the environment as it was
}

}  // namespace qpreduce
