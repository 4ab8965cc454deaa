// qpr — the qpreduce command line. No math lives here: each subcommand calls
// the engine or a plugin and reports.
#include "blas_memory.h"
#include "commands.h"

#include <qpreduce/util/cpu_features.h>

#include <CLI/CLI.hpp>

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <csignal>
#include <cstdio>
#include <cstring>

int main(int argc, char** argv) {
  // Under an address-space limit (`ulimit -v`), OpenBLAS's worker threads,
  // started when the library loads, would each retry their 128 MiB buffer
  // for ever once it no longer fits (and the exit would wait for them): run
  // it on the calling thread only, whose buffer reserve_blas_buffers checks
  // and takes up front (blas_memory.h). The variable must be set before the
  // library loads, hence a fresh start of this program with it.
  if (qpr::single_threaded_blas_under_limit(argv)) return 2;
  // Where Debian's OpenBLAS runs its generic kernels on a CPU newer than it
  // knows, a fresh start with the kernels for this CPU (cpu_features.h).
  qpreduce::restart_with_blas_core(argv);
  // Past a file-size limit a write then fails with EFBIG, which the writers
  // report (leaving the earlier file), instead of SIGXFSZ ending the process.
  std::signal(SIGXFSZ, SIG_IGN);
  // With the standard output closed (`qpr … >&-`) the next file opened would
  // take its descriptor and receive the tables: refuse before opening any.
  if (fcntl(STDOUT_FILENO, F_GETFD) == -1) {
    std::fprintf(stderr, "qpr: error: the standard output is closed (redirect it to a file or /dev/null)\n");
    return 2;
  }
  CLI::App app{"qpr — interactive solves of constrained QPs through linear variational subspaces (qpreduce)"};
  app.name("qpr");
  app.require_subcommand(1);
  qpr::register_demo(app);
  qpr::register_deform(app);
  qpr::register_compare(app);
  qpr::register_theorem(app);
  qpr::register_qp(app);
  qpr::register_check(app);
#ifdef QPREDUCE_HAVE_VIEWER
  qpr::register_view(app);
#endif
#ifdef QPREDUCE_HAVE_MPI
  qpr::register_precompute(app);
#endif
  int code = 0;
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    code = app.exit(e);
  }
  // A command whose output could not be written has failed (`qpr check
  // MESH > /dev/full`, stdout closed): say so, and exit 2 unless it failed
  // already. A failing stderr can only be told by the exit code.
  if (std::fflush(stdout) != 0 || std::ferror(stdout)) {
    const int error = errno;
    std::fprintf(stderr, "qpr: error: writing the standard output failed: %s\n", std::strerror(error));
    if (code == 0) code = 2;
  }
  if ((std::fflush(stderr) != 0 || std::ferror(stderr)) && code == 0) code = 2;
  return code;
}
