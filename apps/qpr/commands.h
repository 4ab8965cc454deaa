// qpr — one subcommand per file (cmd_<name>.cpp), each registered by one
// function declared here and called from main.cpp. A command that fails
// throws CLI::RuntimeError(exit_code) (CLI11 then exits with that code
// without printing anything more); messages go to stderr first.
#pragma once

namespace CLI {
class App;
}

namespace qpr {

// `qpr theorem`: Theorem 4.10 on seeded trials (cmd_theorem.cpp, docs/theorem.md).
void register_theorem(CLI::App& app);
// `qpr demo`: reduced ARAP on a built-in cylinder, no files (cmd_demo.cpp).
void register_demo(CLI::App& app);
// `qpr deform`: reduced ARAP of a mesh from files (cmd_deform.cpp, docs/deform.md).
void register_deform(CLI::App& app);
// `qpr qp`: any QP from Matrix Market files, many demands (cmd_qp.cpp, docs/examples/qp_files.md).
void register_qp(CLI::App& app);
// `qpr compare`: reduced ARAP against full-space references (cmd_compare.cpp, docs/quality.md).
void register_compare(CLI::App& app);
// `qpr check`: mesh pre-flight diagnostics (cmd_check.cpp, docs/robustness.md).
void register_check(CLI::App& app);

// `qpr view`: interactive deformation viewer, headless screenshots (cmd_view.cpp, docs/viewer.md);
// built when QPREDUCE_BUILD_VIEWER is on (QPREDUCE_HAVE_VIEWER).
void register_view(CLI::App& app);

// `qpr precompute`: the deformer's precompute on MUMPS over MPI, into a model
// cache (cmd_precompute.cpp, docs/scaling.md); built when QPREDUCE_WITH_MPI
// is on (QPREDUCE_HAVE_MPI).
void register_precompute(CLI::App& app);

}  // namespace qpr
