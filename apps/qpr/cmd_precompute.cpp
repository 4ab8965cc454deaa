// `qpr precompute MESH … --backend mumps --cache OUT`, under `mpirun -np K`:
// the deformer's precompute with its subspace built by MUMPS over the K ranks
// (qpreduce::distributed), the model cache written by rank 0 in the format
// `qpr deform --cache` loads (docs/scaling.md). Built with QPREDUCE_WITH_MPI.
// No math here: the plugin assembles, qpreduce::distributed builds.
#include "commands.h"
#include "deform_run.h"
#include "guard.h"

#include <qpreduce/distributed/mumps_subspace.h>

#include <CLI/CLI.hpp>
#include <fmt/format.h>
#include <mpi.h>
#include <sys/resource.h>

#include <cstdio>
#include <stdexcept>
#include <vector>

namespace qpr {

namespace {

using qpreduce::distributed::DistributedSummary;

struct PrecomputeArgs : ScenarioArgs {
  std::string cache;
  std::string backend = "mumps";
  int block = 64;
};

double peak_rss_megabytes() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  return static_cast<double>(usage.ru_maxrss) / 1024.0;  // ru_maxrss is in KB on Linux
}

// MPI for the length of the command: initialized here unless the caller has
// (a plain run is a singleton job of one rank).
struct MpiSession {
  MpiSession() {
    int initialized = 0;
    MPI_Initialized(&initialized);
    if (!initialized) MPI_Init(nullptr, nullptr);
    MPI_Comm_rank(MPI_COMM_WORLD, &rank);
    MPI_Comm_size(MPI_COMM_WORLD, &size);
  }
  int rank = 0, size = 1;
};

// The deformer's subspace step on MUMPS: every rank hands over its rows of
// H_u; N and UD are gathered to rank 0 by column blocks, the other ranks end
// precompute after the collective build with Status::NotRun.
qpreduce::deform::Deformer::SubspaceBuilder mumps_builder(const MpiSession& mpi, int block,
                                                          DistributedSummary* record) {
  return [&mpi, block, record](const qpreduce::SparseMatrix<double>& H, const qpreduce::SparseMatrix<double>& C,
                               const qpreduce::SparseMatrix<double>& D, const qpreduce::SubspaceOptions& options,
                               qpreduce::VariationalSubspace<double>* B, qpreduce::Matrix<double>* Hr,
                               qpreduce::Matrix<double>* BtD) {
    const auto rows = qpreduce::distributed::owned_rows(H.rows(), MPI_COMM_WORLD);
    qpreduce::distributed::DistributedSubspace part;
    qpreduce::SubspaceOptions opts = options;
    opts.block_size = block;
    *record = qpreduce::distributed::build_subspace_mumps(
        MPI_COMM_WORLD, H.middleRows(rows.begin, rows.size()), C, D, opts, {}, &part);
    qpreduce::SubspaceSummary summary = *record;
    if (!summary.ok()) return summary;
    qpreduce::distributed::gather_subspace(MPI_COMM_WORLD, part, 0, block, B);
    *Hr = std::move(part.Hr);
    *BtD = std::move(part.BtD);
    if (mpi.rank != 0) {
      summary.status = qpreduce::Status::NotRun;
      summary.message = "the subspace was gathered on rank 0";
    }
    return summary;
  };
}

int run_precompute(const PrecomputeArgs& a, const MpiSession& mpi) {
  if (a.backend != "mumps" && a.backend != "cholmod") {
    throw std::invalid_argument(fmt::format("--backend: expected mumps or cholmod, got \"{}\"", a.backend));
  }
  if (a.backend == "cholmod" && mpi.size > 1) {
    throw std::invalid_argument(
        fmt::format("--backend cholmod runs on one process; got {} MPI ranks (use --backend mumps)", mpi.size));
  }
  if (a.block < 1) throw std::invalid_argument(fmt::format("--block: expected at least 1, got {}", a.block));
  if (mpi.rank == 0) qpreduce::check_destination(a.cache, "cache");
  LoadedScenario ls = load_scenario(a);
  qpreduce::deform::Deformer deformer;
  DistributedSummary dist;
  const qpreduce::Timer total;
  const auto pre = a.backend == "mumps"
                       ? deformer.precompute(ls.scenario.model, ls.options, {}, mumps_builder(mpi, a.block, &dist))
                       : deformer.precompute(ls.scenario.model, ls.options);
  const double seconds = total.seconds();
  // Every rank's peak memory, printed by rank 0.
  const double mine = peak_rss_megabytes();
  std::vector<double> peaks(static_cast<size_t>(mpi.size));
  MPI_Gather(&mine, 1, MPI_DOUBLE, peaks.data(), 1, MPI_DOUBLE, 0, MPI_COMM_WORLD);
  if (a.backend == "mumps" && !dist.ok()) {
    if (mpi.rank == 0) std::fprintf(stderr, "qpr precompute: %s\n", dist.brief_report().c_str());
    return 3;
  }
  if (mpi.rank != 0) return 0;
  if (!pre.ok()) {
    std::fprintf(stderr, "qpr precompute: %s: %s\n", qpreduce::to_string(pre.status), pre.message.c_str());
    return 3;
  }
  deformer.save(a.cache);
  std::printf("%s: precomputed with %s on %d rank(s) in %.2f s (subspace %.2f s)\n", ls.name.c_str(),
              a.backend.c_str(), mpi.size, seconds, pre.subspace_seconds);
  if (a.backend == "mumps") {
    std::printf("  MUMPS: ordering %s, factorization %.2f s, solves %.2f s, reduction %.2f s, factor entries %lld, "
                "MUMPS memory max/total %.0f/%.0f MB\n",
                dist.ordering.c_str(), dist.factorize_seconds, dist.solve_seconds, dist.reduce_seconds,
                static_cast<long long>(dist.factor_nonzeros), dist.factor_megabytes_max, dist.factor_megabytes_total);
  }
  std::printf("  n_u = %lld, p = %lld, KKT residual %.2e\n", static_cast<long long>(pre.subspace.n),
              static_cast<long long>(pre.subspace.d + pre.subspace.k), pre.subspace.kkt_residual);
  for (int r = 0; r < mpi.size; ++r) std::printf("  rank %d peak RSS %.0f MB\n", r, peaks[static_cast<size_t>(r)]);
  std::printf("  cache written: %s\n", a.cache.c_str());
  return 0;
}

}  // namespace

void register_precompute(CLI::App& app) {
  auto [cmd, a] = add_command<PrecomputeArgs>(
      app, "precompute", "Precompute a deformation model into a cache, on MUMPS over MPI (mpirun -np K qpr precompute …)");
  add_scenario_options(cmd, a.get());
  cmd->add_option("--cache", a->cache, "Model cache to write (qpr deform --cache loads it)")->required();
  cmd->add_option("--backend", a->backend, "mumps (MPI, any number of ranks) or cholmod (one process)")
      ->capture_default_str();
  cmd->add_option("--block", a->block, "Right-hand sides per MUMPS solve and columns per gather")
      ->capture_default_str();
  cmd->callback([a = a]() {
    const MpiSession mpi;
    int code = 0;
    try {
      run_guarded("precompute", [&] { return run_precompute(*a, mpi); });
    } catch (const CLI::RuntimeError& e) {
      code = e.get_exit_code();
    }
    // A rank that failed alone would leave the others waiting in a
    // collective: end the whole job instead.
    if (code != 0 && mpi.size > 1) MPI_Abort(MPI_COMM_WORLD, code);
    MPI_Finalize();
    if (code != 0) throw CLI::RuntimeError(code);
  });
}

}  // namespace qpr
