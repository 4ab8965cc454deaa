// qpr — the qpreduce command line. No math lives here: each subcommand calls
// the engine or a plugin and reports.
#include "commands.h"

#include <CLI/CLI.hpp>

#include <csignal>

int main(int argc, char** argv) {
  // Past a file-size limit a write then fails with EFBIG, which the writers
  // report (leaving the earlier file), instead of SIGXFSZ ending the process.
  std::signal(SIGXFSZ, SIG_IGN);
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
  CLI11_PARSE(app, argc, argv);
  return 0;
}
