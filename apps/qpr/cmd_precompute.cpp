// `qpr precompute MESH … --backend mumps --cache OUT`, under `mpirun -np K`:
// the deformer's precompute with its subspace built by MUMPS over the K ranks
// (qpreduce::distributed, Deformer::precompute_part: each rank keeps its rows
// of the basis), the model cache written by rank 0 with every rank's rows of
// the float basis, in the format `qpr deform --cache` loads
// (docs/scaling.md). Built with QPREDUCE_WITH_MPI.
// No math here: the plugin assembles, qpreduce::distributed builds.
#include "commands.h"
#include "deform_run.h"
#include "guard.h"
#include "mpi_session.h"
#include "validators.h"

#include <qpreduce/distributed/mumps_subspace.h>
#include <qpreduce/problems/families.h>
#include <qpreduce/subspace_solver.h>

#include <CLI/CLI.hpp>
#include <fmt/format.h>
#include <mpi.h>
#include <malloc.h>
#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <memory>
#include <stdexcept>
#include <vector>

namespace qpr {

namespace {

using qpreduce::distributed::DistributedSummary;

struct PrecomputeArgs : ScenarioArgs {
  std::string cache;
  std::string backend = "mumps";
  // The host holds one n × block right-hand side: 16 keeps it small at the same speed (docs/scaling.md).
  int block = 16;
  std::string out_of_core;  // MUMPS's factor on disk in this directory (MumpsOptions::out_of_core_directory)
  bool trace_memory = false;
};

double current_rss_megabytes() {
  std::FILE* f = std::fopen("/proc/self/statm", "r");
  long pages = 0, resident = 0;
  if (f == nullptr) return 0.0;
  if (std::fscanf(f, "%ld %ld", &pages, &resident) != 2) resident = 0;
  std::fclose(f);
  return static_cast<double>(resident) * static_cast<double>(sysconf(_SC_PAGESIZE)) / 1048576.0;
}

double peak_rss_megabytes() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  return static_cast<double>(usage.ru_maxrss) / 1024.0;  // ru_maxrss is in KB on Linux
}

// The deformer's subspace step on MUMPS: every rank hands over its rows of
// H_u and keeps its rows of N and UD (Deformer::precompute_part); nothing is
// gathered.
qpreduce::deform::Deformer::PartBuilder mumps_builder(int block, const qpreduce::distributed::MumpsOptions& mumps,
                                                      DistributedSummary* record) {
  return [block, mumps, record](const qpreduce::SparseMatrix<double>& H, const qpreduce::SparseMatrix<double>& C,
                         const qpreduce::SparseMatrix<double>& D, const qpreduce::SubspaceOptions& options,
                         qpreduce::deform::Deformer::SubspacePart* part) {
    qpreduce::SubspaceOptions opts = options;
    opts.block_size = block;
    qpreduce::distributed::DistributedSubspace mine;
    *record = qpreduce::distributed::build_subspace_mumps_rows(MPI_COMM_WORLD, H, C, D, opts, mumps, &mine);
    part->first_row = mine.rows.begin;
    part->N_rows = std::move(mine.N_rows);
    part->UD_rows = std::move(mine.UD_rows);
    part->Hr = std::move(mine.Hr);
    part->BtD = std::move(mine.BtD);
    return qpreduce::SubspaceSummary(*record);
  };
}

// glibc serves large blocks from its heap once a freed mmap'd block has
// raised its (dynamic) mmap threshold, and a heap fragmented by the
// assembly's temporaries keeps them resident under the subspace build. A
// fixed 1 MiB threshold sends every block of 1 MiB or more (sparse
// matrices, dense blocks) to mmap and back to the system when freed:
// on the Bumpy Plane it lowered the peak resident memory of rank 0 of
// `-np 2` and of one process by 4–11 % (one run each). Only this
// command: it runs once, while frames and refines reuse their buffers.
void return_large_blocks_to_the_system() {
#ifdef __GLIBC__
  mallopt(M_MMAP_THRESHOLD, 1 << 20);
#endif
}

// The MUMPS options the arguments ask for; throws std::invalid_argument
// naming the option that does not fit the backend or the ranks.
qpreduce::distributed::MumpsOptions mumps_options(const PrecomputeArgs& a, const MpiSession& mpi) {
  if (a.backend != "mumps" && a.backend != "cholmod") {
    throw std::invalid_argument(fmt::format("--backend: expected mumps or cholmod, got \"{}\"", a.backend));
  }
  if (a.backend == "cholmod" && mpi.size > 1) {
    throw std::invalid_argument(
        fmt::format("--backend cholmod runs on one process; got {} MPI ranks (use --backend mumps)", mpi.size));
  }
  if (a.block < 1) throw std::invalid_argument(fmt::format("--block: expected at least 1, got {}", a.block));
  if (!a.out_of_core.empty() && a.backend != "mumps") {
    throw std::invalid_argument("--out-of-core: only with --backend mumps (CHOLMOD keeps its factor in memory)");
  }
  qpreduce::distributed::MumpsOptions mumps;
  mumps.out_of_core_directory = a.out_of_core;
  std::string why;
  if (!mumps.is_valid(&why)) throw std::invalid_argument("--out-of-core: " + why);
  if (!a.out_of_core.empty() && !std::filesystem::is_directory(a.out_of_core)) {
    throw std::invalid_argument(
        fmt::format("--out-of-core: \"{}\" is not a directory (on rank {})", a.out_of_core, mpi.rank));
  }
  return mumps;
}

int run_precompute(const PrecomputeArgs& a, const MpiSession& mpi) {
  return_large_blocks_to_the_system();
  const qpreduce::distributed::MumpsOptions mumps = mumps_options(a, mpi);
  if (mpi.rank == 0) qpreduce::check_destination(a.cache, "cache");
  LoadedScenario ls = load_scenario(a);
  qpreduce::deform::Deformer deformer;
  DistributedSummary dist;
  const qpreduce::Timer total;
  // --trace-memory: every rank's peak and current RSS at each stage.
  const qpreduce::deform::ProgressFn trace = [&](const std::string& stage, double) {
    if (!a.trace_memory) return;
    std::fprintf(stderr, "rank %d at %s: peak %.0f MB, now %.0f MB\n", mpi.rank, stage.c_str(), peak_rss_megabytes(),
                 current_rss_megabytes());
  };
  const auto pre = a.backend == "mumps" ? deformer.precompute_part(ls.scenario.model, ls.options, trace, {mpi.rank, mpi.size},
                                                                   mumps_builder(a.block, mumps, &dist),
                                                                   [](qpreduce::Matrix<double>* M) {
                                                                     qpreduce::distributed::sum_over_ranks(MPI_COMM_WORLD, M);
                                                                   })
                                        : deformer.precompute(ls.scenario.model, ls.options, trace);
  if (a.backend == "mumps" && !dist.ok()) {  // the same status on every rank
    if (mpi.rank == 0) std::fprintf(stderr, "qpr precompute: %s\n", dist.brief_report().c_str());
    return 3;
  }
  if (!pre.ok()) {
    if (mpi.rank == 0)
      std::fprintf(stderr, "qpr precompute: %s: %s\n", qpreduce::to_string(pre.status), pre.message.c_str());
    return 3;
  }
  trace("saving", 1.0);
  // The cache, written by rank 0 with every rank's rows of the float basis.
  // It travels to rank 0 in chunks made from each rank's double rows as they
  // go (Deformer::basis_block): no rank holds the float basis whole.
  const auto rows = deformer.basis_rows();
  const qpreduce::distributed::NextRows next = qpreduce::distributed::stream_rows_to_root(
      MPI_COMM_WORLD, 0, {rows.first, rows.first + rows.count}, pre.reduced_size,
      [&deformer](qpreduce::Index first, qpreduce::Index count, qpreduce::distributed::FloatRows* block) {
        deformer.basis_block(first, count, block);
      });
  if (mpi.rank == 0) deformer.save(run_files().stage(a.cache), next);
  const double seconds = total.seconds();
  // Every rank's peak memory, printed by rank 0.
  const std::vector<double> peaks = qpreduce::distributed::gather_values(
      MPI_COMM_WORLD, {peak_rss_megabytes(), static_cast<double>(pre.assembled_elements)}, 0);
  if (mpi.rank != 0) return 0;
  std::printf("%s: precomputed with %s on %d rank(s) in %.2f s (subspace %.2f s), cache written\n", ls.name.c_str(),
              a.backend.c_str(), mpi.size, seconds, pre.subspace_seconds);
  if (a.backend == "mumps") {
    std::printf("  MUMPS%s: ordering %s, factorization %.2f s, solves %.2f s, reduction %.2f s, factor entries %lld, "
                "MUMPS memory max/total %.0f/%.0f MB\n",
                a.out_of_core.empty() ? "" : " (factor out of core)", dist.ordering.c_str(), dist.factorize_seconds, dist.solve_seconds, dist.reduce_seconds,
                static_cast<long long>(dist.factor_nonzeros), dist.factor_megabytes_max, dist.factor_megabytes_total);
  }
  std::printf("  n_u = %lld, p = %lld, KKT residual %.2e\n", static_cast<long long>(pre.subspace.n),
              static_cast<long long>(pre.subspace.d + pre.subspace.k), pre.subspace.kkt_residual);
  for (int r = 0; r < mpi.size; ++r) {
    std::printf("  rank %d peak RSS %.0f MB, assembled %.0f of the %lld rotation elements\n", r,
                peaks[2 * static_cast<size_t>(r)], peaks[2 * static_cast<size_t>(r) + 1],
                static_cast<long long>(pre.elements));
  }
  std::printf("  cache written: %s\n", a.cache.c_str());
  return 0;
}

struct GmrfArgs {
  long side = 300, candidates = 200;
  std::string backend = "mumps";
  int block =
      16;  // the host holds one n × block right-hand side: 16 keeps it small at the same speed (docs/scaling.md)
};

// The engine alone on the seeded GMRF grid (qpreduce/problems, families.h):
// with mumps nothing is gathered (each rank keeps its rows of N and UD);
// with cholmod the single-process SubspaceSolver. Prints time and the
// peak memory of every rank.
int run_gmrf(const GmrfArgs& a, const MpiSession& mpi) {
  if (a.backend != "mumps" && a.backend != "cholmod") {
    throw std::invalid_argument(fmt::format("--backend: expected mumps or cholmod, got \"{}\"", a.backend));
  }
  if (a.backend == "cholmod" && mpi.size > 1) {
    throw std::invalid_argument(fmt::format("--backend cholmod runs on one process; got {} MPI ranks", mpi.size));
  }
  if (a.block < 1) throw std::invalid_argument(fmt::format("--block: expected at least 1, got {}", a.block));
  qpreduce::families::GmrfOptions g;
  g.nx = g.ny = a.side;
  g.candidates = a.candidates;
  g.observed = std::min<qpreduce::Index>(g.observed, a.candidates);
  std::string why;
  if (!g.is_valid(&why)) throw std::invalid_argument("GMRF grid: " + why);
  const qpreduce::Timer total;
  qpreduce::SubspaceOptions options;
  options.augment = !(g.ridge > 0.0);  // as recommended_options: augmented while ker H = constants
  options.block_size = a.block;
  qpreduce::SubspaceSummary summary;
  std::string detail;
  const qpreduce::Index n = g.nx * g.ny, k = g.trend;
  if (a.backend == "mumps") {
    // Each rank makes only its rows of H and D (make_gmrf_rows); C whole.
    const auto rows = qpreduce::distributed::owned_rows(n, MPI_COMM_WORLD);
    const auto mine = qpreduce::families::make_gmrf_rows(g, rows.begin, rows.end);
    qpreduce::distributed::DistributedSubspace part;
    const auto dist = qpreduce::distributed::build_subspace_mumps_rows(
        MPI_COMM_WORLD, mine.H, qpreduce::families::make_gmrf_design(g), mine.D, options, {}, &part);
    summary = dist;
    detail = fmt::format("ordering {}, factorization {:.2f} s, solves {:.2f} s, reduction {:.2f} s, MUMPS memory "
                         "max/total {:.0f}/{:.0f} MB",
                         dist.ordering, dist.factorize_seconds, dist.solve_seconds, dist.reduce_seconds,
                         dist.factor_megabytes_max, dist.factor_megabytes_total);
  } else {
    const auto family = qpreduce::families::make_gmrf(g);
    options = qpreduce::families::recommended_options(family);
    options.block_size = a.block;
    qpreduce::SubspaceSolver<double> solver;
    summary = solver.precompute(family.H, family.C, family.D, options);
    detail = fmt::format("factorization {:.2f} s, solves {:.2f} s", summary.factorize_seconds, summary.solve_seconds);
  }
  const double seconds = total.seconds();
  const std::vector<double> peaks = qpreduce::distributed::gather_values(MPI_COMM_WORLD, {peak_rss_megabytes()}, 0);
  if (mpi.rank != 0) return summary.ok() ? 0 : 3;
  std::printf(
      "gmrf %ld × %ld (n = %lld, d = %lld, k = %lld) with %s on %d rank(s): %.2f s (build %.2f s)\n  %s\n  %s\n",
      a.side, a.side, static_cast<long long>(n), static_cast<long long>(g.candidates), static_cast<long long>(k),
      a.backend.c_str(), mpi.size, seconds, summary.total_seconds,
      summary.brief_report().c_str(), detail.c_str());
  for (int r = 0; r < mpi.size; ++r) std::printf("  rank %d peak RSS %.0f MB\n", r, peaks[static_cast<size_t>(r)]);
  return summary.ok() ? 0 : 3;
}

}  // namespace

void register_precompute(CLI::App& app) {
  auto [cmd, a] = add_command<PrecomputeArgs>(
      app, "precompute",
      "Precompute a deformation model into a cache, on MUMPS over MPI (mpirun -np K qpr precompute …)");
  add_scenario_options(cmd, a.get());
  add_path_option(cmd, PathRole::Cache, "--cache", a->cache, "Model cache to write (qpr deform --cache loads it)")->required();
  cmd->add_option("--backend", a->backend, "mumps (MPI, any number of ranks) or cholmod (one process)")
      ->capture_default_str();
  cmd->add_option("--block", a->block, "Right-hand sides per MUMPS solve")
      ->check(whole_number_between(1, 4096))
      ->capture_default_str();
  cmd->add_option("--out-of-core", a->out_of_core,
                  "Directory (on every rank, e.g. a local disk) where MUMPS keeps its factor instead of memory")
      ->type_name("DIR");
  cmd->add_flag("--trace-memory", a->trace_memory,
                "Print every rank's peak and current resident memory at each precompute stage (stderr)");
  cmd->callback([a = a, command = cmd]() {
    run_with_mpi("precompute", *command, [&](const MpiSession& mpi) { return run_precompute(*a, mpi); });
  });

  auto [gmrf, g] = add_command<GmrfArgs>(
      app, "precompute-gmrf", "Subspace build of the seeded GMRF grid family, for scaling runs (mpirun -np K …)");
  gmrf->add_option("--side", g->side, "grid vertices per side; n = side²")
      ->check(whole_number_between(2, 100000))
      ->capture_default_str();
  gmrf->add_option("--candidates", g->candidates, "candidate sites d")
      ->check(whole_number_between(1, 1000000))
      ->capture_default_str();
  gmrf->add_option("--backend", g->backend, "mumps (MPI, any number of ranks) or cholmod (one process)")
      ->capture_default_str();
  gmrf->add_option("--block", g->block, "right-hand sides per MUMPS solve")
      ->check(whole_number_between(1, 4096))
      ->capture_default_str();
  gmrf->callback([g = g, command = gmrf]() {
    run_with_mpi("precompute-gmrf", *command, [&](const MpiSession& mpi) { return run_gmrf(*g, mpi); });
  });
}

}  // namespace qpr
