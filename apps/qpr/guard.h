// qpr — add a subcommand with its options, and run a subcommand body,
// turning failures into a message on stderr and an exit code
// (CLI::RuntimeError), never an uncaught exception.
#pragma once

#include <CLI/CLI.hpp>

#include <cstdio>
#include <exception>
#include <functional>
#include <memory>
#include <new>
#include <string>
#include <utility>

namespace qpr {

// body returns the exit code; 0 returns normally. Exceptions other than
// CLI11's own print "qpr <name>: error: <what>" and exit with code 2; running
// out of memory says so in words ("out of memory …") instead of
// "std::bad_alloc". Every subcommand's callback goes through here.
inline void run_guarded(const char* name, const std::function<int()>& body) {
  int code = 0;
  try {
    code = body();
  } catch (const CLI::Error&) {
    throw;
  } catch (const std::bad_alloc&) {
    std::fprintf(stderr, "qpr %s: error: out of memory (the inputs or options ask for more than this machine has)\n",
                 name);
    throw CLI::RuntimeError(2);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "qpr %s: error: %s\n", name, e.what());
    throw CLI::RuntimeError(2);
  } catch (...) {
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
