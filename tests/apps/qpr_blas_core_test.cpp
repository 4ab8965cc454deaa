// The BLAS kernels qpr runs (qpreduce/util/cpu_features.h): the choice of
// OPENBLAS_CORETYPE from this CPU's features, its respect for a value the
// user set, and qpr's fresh start where Debian's OpenBLAS falls back to its
// generic kernels.
#include <qpreduce/util/cpu_features.h>

#include <catch2/catch.hpp>

#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <optional>
#include <string>

#ifndef QPR_BINARY
#error "QPR_BINARY must name the qpr executable"
#endif

namespace {

// Sets (or, with nullopt, unsets) an environment variable for one scope.
class ScopedEnv {
 public:
  ScopedEnv(const char* name, std::optional<std::string> value) : name_(name) {
    if (const char* old = std::getenv(name)) old_ = old;
    if (value) setenv(name, value->c_str(), 1);
    else unsetenv(name);
  }
  ~ScopedEnv() {
    if (old_) setenv(name_, old_->c_str(), 1);
    else unsetenv(name_);
  }
  ScopedEnv(const ScopedEnv&) = delete;
  ScopedEnv& operator=(const ScopedEnv&) = delete;

 private:
  const char* name_;
  std::optional<std::string> old_;
};

// The core OpenBLAS names last in `qpr --help`'s verbose start-up ("Core: X"
// once per load of the library), or "" when it named none.
std::string qpr_core() {
  FILE* pipe = popen((std::string("OPENBLAS_VERBOSE=2 ") + QPR_BINARY + " --help 2>&1").c_str(), "r");
  REQUIRE(pipe != nullptr);
  std::string core;
  char line[512];
  while (std::fgets(line, sizeof line, pipe) != nullptr) {
    if (std::strncmp(line, "Core: ", 6) != 0) continue;
    core = line + 6;
    while (!core.empty() && (core.back() == '\n' || core.back() == ' ')) core.pop_back();
  }
  REQUIRE(pclose(pipe) == 0);
  return core;
}

}  // namespace

TEST_CASE("preferred_blas_core names a family this CPU can run", "[blas]") {
  const std::string preferred = qpreduce::preferred_blas_core();
  CHECK((preferred.empty() || preferred == "Haswell" || preferred == "SkylakeX"));
#if defined(__x86_64__) && defined(__GNUC__)
  __builtin_cpu_init();
  if (!preferred.empty()) {
    CHECK(__builtin_cpu_is("intel"));
    CHECK(__builtin_cpu_supports("avx2"));
    CHECK(__builtin_cpu_supports("fma"));
  }
  if (preferred == "SkylakeX") {
    CHECK(__builtin_cpu_supports("avx512f"));
    CHECK(__builtin_cpu_supports("avx512bw"));
    CHECK(__builtin_cpu_supports("avx512vl"));
  }
#endif
}

TEST_CASE("prefer_blas_core keeps a value the user chose", "[blas]") {
  const std::string preferred = qpreduce::preferred_blas_core();
  {
    ScopedEnv core("OPENBLAS_CORETYPE", std::string("Sandybridge"));
    ScopedEnv keep("QPREDUCE_KEEP_BLAS_CORE", std::nullopt);
    CHECK_FALSE(qpreduce::prefer_blas_core());
    CHECK(std::string(std::getenv("OPENBLAS_CORETYPE")) == "Sandybridge");
  }
  {
    ScopedEnv core("OPENBLAS_CORETYPE", std::nullopt);
    ScopedEnv keep("QPREDUCE_KEEP_BLAS_CORE", std::string("1"));
    CHECK_FALSE(qpreduce::prefer_blas_core());
    CHECK(std::getenv("OPENBLAS_CORETYPE") == nullptr);
  }
  {
    ScopedEnv core("OPENBLAS_CORETYPE", std::nullopt);
    ScopedEnv keep("QPREDUCE_KEEP_BLAS_CORE", std::nullopt);
    CHECK(qpreduce::prefer_blas_core() == !preferred.empty());
    const char* set = std::getenv("OPENBLAS_CORETYPE");
    if (preferred.empty()) CHECK(set == nullptr);
    else CHECK(std::string(set) == preferred);
  }
}

TEST_CASE("qpr runs OpenBLAS's kernels for this CPU where OpenBLAS falls back to generic ones", "[blas]") {
  // This test program does not restart: its OpenBLAS made its own choice.
  const std::string own = qpreduce::blas_core();
  if (own.empty()) {
    WARN("skipped: the BLAS is not OpenBLAS");
    return;
  }
  if (std::getenv("OPENBLAS_CORETYPE") != nullptr || std::getenv("QPREDUCE_KEEP_BLAS_CORE") != nullptr) {
    WARN("skipped: OPENBLAS_CORETYPE or QPREDUCE_KEEP_BLAS_CORE is set, and qpr keeps that choice");
    return;
  }
  const std::string preferred = qpreduce::preferred_blas_core();
  const std::string expected = own == "Prescott" && !preferred.empty() ? preferred : own;
  INFO("this program's OpenBLAS runs " << own << "; preferred: '" << preferred << "'");
  CHECK(qpr_core() == expected);
  // Asked to keep OpenBLAS's choice, qpr does.
  ScopedEnv keep("QPREDUCE_KEEP_BLAS_CORE", std::string("1"));
  CHECK(qpr_core() == own);
}
