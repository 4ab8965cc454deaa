// qpr — add a subcommand with its options, and run a subcommand body,
// turning failures into a message on stderr and an exit code
// (CLI::RuntimeError), never an uncaught exception, and committing the run's
// outputs only when it succeeded (run_files.h).
#pragma once

#include "blas_memory.h"
#include "path_roles.h"
#include "run_files.h"

#include <CLI/CLI.hpp>

#include <algorithm>
#include <initializer_list>

#include <cstdio>
#include <exception>
#include <functional>
#include <memory>
#include <new>
#include <string>
#include <utility>

namespace qpr {

// body returns the exit code; 0 returns normally. The outputs the body
// staged (run_files()) are put in place when it returns 0 or one of the
// command's `verdicts` (exit codes that report a finding, not a failure:
// qpr check's 1 and 2, a violated bound's 1), and removed otherwise: a
// failing run writes nothing. Exceptions other than CLI11's own print
// "qpr <name>: error: <what>" and exit with code 2; running out of memory
// says so in words ("out of memory …") instead of "std::bad_alloc". Every
// subcommand's callback goes through here.
// Unless `linear_algebra` is false (qpr check), the BLAS work buffers are
// reserved first under an address-space limit (blas_memory.h).
inline void run_guarded(const char* name, const std::function<int()>& body, std::initializer_list<int> verdicts = {},
                        bool linear_algebra = true) {
  RunFiles& outputs = run_files();
  outputs.discard();  // nothing staged by an earlier run of this process
  int code = 0;
  try {
    check_path_roles(name);  // no output may be an input (path_roles.h)
    if (linear_algebra) reserve_blas_buffers();
    code = body();
    if (code == 0 || std::find(verdicts.begin(), verdicts.end(), code) != verdicts.end()) {
      outputs.commit();
    } else {
      outputs.discard();
    }
  } catch (const CLI::Error&) {
    outputs.discard();
    throw;
  } catch (const std::bad_alloc&) {
    outputs.discard();
    std::fprintf(stderr, "qpr %s: error: out of memory (the inputs or options ask for more than this machine has)\n",
                 name);
    throw CLI::RuntimeError(2);
  } catch (const std::exception& e) {
    const std::string what = outputs.plain(e.what());
    outputs.discard();
    std::fprintf(stderr, "qpr %s: error: %s\n", name, what.c_str());
    throw CLI::RuntimeError(2);
  } catch (...) {
    outputs.discard();
    std::fprintf(stderr, "qpr %s: error: unknown exception\n", name);
    throw CLI::RuntimeError(2);
  }
  if (code != 0) throw CLI::RuntimeError(code);
}

// Adds the subcommand `name` to `app`; returns it and a fresh Options that
// its option definitions fill and its callback reads (shared, so that the
// callback may keep it).
template <typename Options>
std::pair<CLI::App*, std::shared_ptr<Options>> add_command(CLI::App& app, const std::string& name,
                                                           const std::string& description) {
  return {app.add_subcommand(name, description), std::make_shared<Options>()};
}

}  // namespace qpr
