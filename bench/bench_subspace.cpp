// Benchmark: building the variational subspace (Eq. 4–5) — one sparse
// factorization and d + k solves — and the solver's precompute (the subspace
// plus the reduced matrices H_r = BᵀHB and BᵀD), on 2-D grid Laplacians.
//
// Arguments: side (n = side²), p = d + k, D kind (0 trend, 1 Gaussian; see
// bench_util.h), PSD check (0 off; 1 the default, the certificate from S;
// 2 by factoring H + τI, as before the certificate existed).
// Counters: the summary's KKT residual and phase timings, the factor size,
// and the peak resident memory during the timed call (process-wide, in MiB;
// `extra_MiB` is the peak minus the resident size before the call).
#include "bench_util.h"

#include "qpreduce/subspace.h"
#include "qpreduce/subspace_solver.h"

#include <benchmark/benchmark.h>

namespace {

using namespace qpreduce;
using qpreduce::bench::DKind;

void set_counters(benchmark::State& state, const SubspaceSummary& s, const bench::PeakMemory& mem) {
  state.counters["n"] = static_cast<double>(s.n);
  state.counters["d"] = static_cast<double>(s.d);
  state.counters["k"] = static_cast<double>(s.k);
  state.counters["kkt_residual"] = s.kkt_residual;
  state.counters["factor_nnz_M"] = static_cast<double>(s.factor_nonzeros) * 1e-6;
  state.counters["psd_s"] = s.check_psd_seconds;
  state.counters["factor_s"] = s.factorize_seconds;
  state.counters["solve_s"] = s.solve_seconds;
  state.counters["rest_s"] = s.total_seconds - s.check_psd_seconds - s.factorize_seconds - s.solve_seconds;
  state.counters["peak_MiB"] = mem.peak_mb();
  state.counters["extra_MiB"] = mem.peak_mb() - mem.baseline_mb();
}

SubspaceOptions options_for(benchmark::State& state) {
  SubspaceOptions opts;
  opts.check_psd = state.range(3) != 0;
  opts.psd_check_by_factorization = state.range(3) == 2;
  return opts;
}

const char* psd_label(const SubspaceOptions& opts) {
  if (!opts.check_psd) return "/no-psd";
  return opts.psd_check_by_factorization ? "/psd-factor" : "/psd-certificate";
}

void BM_BuildSubspace(benchmark::State& state) {
  const auto kind = static_cast<DKind>(state.range(2));
  const bench::GridProblem g = bench::make_grid_problem(state.range(0), state.range(1), kind, 0);
  const SubspaceOptions opts = options_for(state);
  VariationalSubspace<double> out;
  SubspaceSummary summary;
  bench::PeakMemory mem;
  for (auto _ : state) {
    state.PauseTiming();
    out = {};  // the previous iteration's result is not part of this one's peak
    mem.reset();
    state.ResumeTiming();
    summary = build_subspace(g.H, g.C, g.D, opts, &out);
    benchmark::DoNotOptimize(out.N.data());
  }
  if (!summary.ok()) state.SkipWithError(summary.brief_report().c_str());
  set_counters(state, summary, mem);
  state.SetLabel(std::string(to_string(summary.backend_used)) + "/" + bench::to_string(kind) + psd_label(opts));
}

void BM_SolverPrecompute(benchmark::State& state) {
  const auto kind = static_cast<DKind>(state.range(2));
  const bench::GridProblem g = bench::make_grid_problem(state.range(0), state.range(1), kind, 0);
  const SubspaceOptions opts = options_for(state);
  SubspaceSummary summary;
  bench::PeakMemory mem;
  for (auto _ : state) {
    state.PauseTiming();
    auto solver = std::make_unique<SubspaceSolver<double>>();
    mem.reset();
    state.ResumeTiming();
    summary = solver->precompute(g.H, g.C, g.D, opts);
    benchmark::DoNotOptimize(solver->reduced_hessian().data());
    state.PauseTiming();
    const double peak = mem.peak_mb();
    solver.reset();
    state.counters["peak_MiB"] = peak;
    state.ResumeTiming();
  }
  if (!summary.ok()) state.SkipWithError(summary.brief_report().c_str());
  const double peak = state.counters["peak_MiB"];
  set_counters(state, summary, mem);
  state.counters["peak_MiB"] = peak;
  state.counters["extra_MiB"] = peak - mem.baseline_mb();
  state.SetLabel(std::string(to_string(summary.backend_used)) + "/" + bench::to_string(kind) + psd_label(opts));
}

// n = side² ∈ {10⁴, 4·10⁴, 9·10⁴, 1.6·10⁵, 2.5·10⁵}; p = d + k ∈ {50, 300};
// D trend; the three PSD-check settings. Gaussian D (k = p/2) at p = 300.
void BuildSizes(benchmark::internal::Benchmark* b) {
  for (int side : {100, 200, 300, 400, 500})
    for (int p : {50, 300})
      for (int psd : {1, 2, 0}) b->Args({side, p, static_cast<int>(DKind::Trend), psd});
  for (int side : {100, 300, 500}) b->Args({side, 300, static_cast<int>(DKind::Gaussian), 1});
}

void PrecomputeSizes(benchmark::internal::Benchmark* b) {
  for (int side : {100, 200, 300, 400, 500}) b->Args({side, 300, static_cast<int>(DKind::Trend), 1});
  for (int side : {100, 300, 500}) b->Args({side, 300, static_cast<int>(DKind::Gaussian), 1});
}

}  // namespace

BENCHMARK(BM_BuildSubspace)
    ->ArgNames({"side", "p", "D", "psd"})
    ->Apply(BuildSizes)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();
BENCHMARK(BM_SolverPrecompute)
    ->ArgNames({"side", "p", "D", "psd"})
    ->Apply(PrecomputeSizes)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

BENCHMARK_MAIN();
