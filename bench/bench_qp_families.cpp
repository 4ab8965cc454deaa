// Benchmark: the three non-graphics QP families (families.h) at
// n ≈ 10⁵, per demand, against the two baselines measured in the same run.
//
//   BM_QpPrecompute     SubspaceSolver::precompute (one factorization,
//                       d + k solves) — once per (H, C, D);
//   BM_QpDemand         a new demand end to end in reduced coordinates:
//                       set_constraints (OP) + solve_in_D; reconstruct:1 also
//                       reconstructs all n values of X; design:1 passes the
//                       constraints as A_c (A = C·A_c) to
//                       set_constraints_in_design, without the nnz(A)·p
//                       product AᵀB; explicit:1 forms the p×p operators
//                       (ConstraintOptions::explicit_operators) where
//                       explicit:0 may keep them factored (in-design
//                       demands, as A_c or as A once drop_tolerance has
//                       zeroed AᵀB's round-off), the A/B of one run;
//   BM_QpSolve          solve_in_D alone (same constraint set, new b and Y;
//                       design and explicit as above);
//   BM_QpCachedSchur    the strongest simple competitor: a Cholesky of
//                       H (+ W·Wᵀ, one pinned site, when H is singular) cached at
//                       set-up, then per demand m + 1 solves, the Schur
//                       complement and X (schur_baseline.h);
//   BM_QpFullKkt        qpreduce::solve_full: a full sparse KKT solve per
//                       demand (factorization included, as a one-off solve).
// Both the subspace and the full solve use families::recommended_options
// (factor H itself when it is PD: the portfolio's long C columns would
// otherwise fill in or push the build onto SparseLU).
// Demands cycle through 16 seeded in-design demands; all set-up (family,
// precompute, baseline factor) is outside the timed loops and cached per
// (family, size).
//
// Arguments: family (0 gmrf, 1 trajectory, 2 portfolio), size (n ≈ size).
#include "qpreduce/problems/families.h"
#include "qpreduce/full_solve.h"
#include "qpreduce/problems/schur_baseline.h"
#include "qpreduce/subspace_solver.h"

#include <benchmark/benchmark.h>

#include <cmath>
#include <map>
#include <memory>
#include <stdexcept>

namespace {

using namespace qpreduce;
using families::Family;

constexpr int kDemands = 16;

// Family instances at benchmark scale: gmrf 317² grid with 300 candidate
// sites and 60 observations per demand; trajectory of 5·10⁴ samples in 2-D
// with 200 stations and 20 waypoints per demand; portfolio of 10⁵ assets, 10
// factors, 50 sectors, 10 of them constrained per demand.
families::QpFamily make(Family f, Index size) {
  switch (f) {
    case Family::Gmrf: {
      families::GmrfOptions o;
      o.nx = o.ny = static_cast<Index>(std::lround(std::sqrt(double(size))));
      o.candidates = 300;
      o.observed = 60;
      return families::make_gmrf(o);
    }
    case Family::Trajectory: {
      families::TrajectoryOptions o;
      o.samples = size / o.dims;
      o.stations = 200;
      o.waypoints = 20;
      return families::make_trajectory(o);
    }
    case Family::Portfolio: {
      families::PortfolioOptions o;
      o.assets = size;
      o.sectors = 50;
      o.neutral = 10;
      return families::make_portfolio(o);
    }
  }
  throw std::invalid_argument("family");
}

struct Fixture {
  families::QpFamily fam;
  std::vector<families::QpDemand> demands;
  SubspaceSolver<double> solver;
  CachedCholeskySchur baseline;
  double precompute_seconds = 0.0, baseline_seconds = 0.0;
};

Fixture& fixture(int family, Index size, bool with_baseline = false) {
  static std::map<std::pair<int, Index>, std::unique_ptr<Fixture>> cache;
  auto& slot = cache[{family, size}];
  if (!slot) {
    slot = std::make_unique<Fixture>();
    Fixture& f = *slot;
    f.fam = make(static_cast<Family>(family), size);
    for (int i = 0; i < kDemands; ++i) f.demands.push_back(families::make_demand(f.fam, static_cast<std::uint64_t>(i)));
    const SubspaceSummary s = f.solver.precompute(f.fam.H, f.fam.C, f.fam.D, families::recommended_options(f.fam));
    if (!s.ok()) throw std::runtime_error(s.brief_report());
    f.precompute_seconds = s.total_seconds;
  }
  Fixture& f = *slot;
  if (with_baseline && !f.baseline.ready()) {
    const SchurBaselineSummary b = f.baseline.precompute(f.fam.H, families::baseline_bordering(f.fam));
    if (!b.ok()) throw std::runtime_error(b.message);
    f.baseline_seconds = b.seconds;
  }
  return f;
}

void counters(benchmark::State& state, const Fixture& f) {
  state.counters["n"] = static_cast<double>(f.fam.n());
  state.counters["p"] = static_cast<double>(f.fam.d() + f.fam.k());
  state.counters["m"] = static_cast<double>(f.demands.front().A.cols());
  state.SetLabel(families::to_string(f.fam.family));
}

void BM_QpPrecompute(benchmark::State& state) {
  const families::QpFamily fam = make(static_cast<Family>(state.range(0)), state.range(1));
  for (auto _ : state) {
    SubspaceSolver<double> solver;
    const SubspaceSummary s = solver.precompute(fam.H, fam.C, fam.D, families::recommended_options(fam));
    if (!s.ok()) state.SkipWithError(s.message.c_str());
    benchmark::DoNotOptimize(solver.p());
  }
  state.counters["n"] = static_cast<double>(fam.n());
  state.SetLabel(families::to_string(fam.family));
}

void BM_QpDemand(benchmark::State& state) {
  Fixture& f = fixture(static_cast<int>(state.range(0)), state.range(1));
  const bool reconstruct = state.range(2) != 0, in_design = state.range(3) != 0;
  ConstraintOptions options;
  options.explicit_operators = state.range(4) != 0;
  Vector<double> w(f.solver.p()), X(f.solver.n());
  int i = 0;
  bool factored = true;
  for (auto _ : state) {
    const families::QpDemand& d = f.demands[static_cast<size_t>(i++ % kDemands)];
    const ConstraintSummary cs =
        in_design ? f.solver.set_constraints_in_design(d.A_c, options) : f.solver.set_constraints(d.A, options);
    if (!cs.usable()) state.SkipWithError(cs.message.c_str());
    factored = factored && cs.factored;
    f.solver.solve_in_D(d.b, d.Y, w);
    if (reconstruct) f.solver.reconstruct(w, X);
    benchmark::DoNotOptimize(w.data());
    benchmark::DoNotOptimize(X.data());
  }
  counters(state, f);
  state.counters["factored"] = factored ? 1.0 : 0.0;  // every demand kept M_q factored
}

void BM_QpSolve(benchmark::State& state) {
  Fixture& f = fixture(static_cast<int>(state.range(0)), state.range(1));
  const families::QpDemand& d0 = f.demands.front();
  ConstraintOptions options;
  options.explicit_operators = state.range(3) != 0;
  const ConstraintSummary cs = state.range(2) != 0 ? f.solver.set_constraints_in_design(d0.A_c, options)
                                                   : f.solver.set_constraints(d0.A, options);
  if (!cs.usable()) state.SkipWithError("set_constraints failed");
  state.counters["factored"] = cs.factored ? 1.0 : 0.0;
  Vector<double> w(f.solver.p());
  int i = 0;
  for (auto _ : state) {
    // Same constraint set, new values: b and Y of another demand (sizes match).
    const families::QpDemand& d = f.demands[static_cast<size_t>(i++ % kDemands)];
    f.solver.solve_in_D(d.b.size() == d0.b.size() ? d.b : d0.b, d.Y, w);
    benchmark::DoNotOptimize(w.data());
  }
  counters(state, f);
}

void BM_QpCachedSchur(benchmark::State& state) {
  Fixture& f = fixture(static_cast<int>(state.range(0)), state.range(1), /*with_baseline=*/true);
  Vector<double> X;
  int i = 0;
  for (auto _ : state) {
    const families::QpDemand& d = f.demands[static_cast<size_t>(i++ % kDemands)];
    const SchurBaselineSummary s = f.baseline.solve(d.A, d.b, d.q, &X);
    if (!s.ok()) state.SkipWithError(s.message.c_str());
    benchmark::DoNotOptimize(X.data());
  }
  counters(state, f);
  state.counters["factor_seconds"] = f.baseline_seconds;
}

void BM_QpFullKkt(benchmark::State& state) {
  Fixture& f = fixture(static_cast<int>(state.range(0)), state.range(1));
  const SubspaceOptions options = families::recommended_options(f.fam);
  Vector<double> X;
  int i = 0;
  for (auto _ : state) {
    const families::QpDemand& d = f.demands[static_cast<size_t>(i++ % kDemands)];
    const FullSolveSummary s = solve_full(f.fam.H, d.A, d.b, d.q, &X, options);
    if (!s.ok()) state.SkipWithError(s.message.c_str());
    benchmark::DoNotOptimize(X.data());
  }
  counters(state, f);
}

// Sizes: 10⁵ (the target) and 10⁴ (for scaling and the CI smoke test).
void families_and_sizes(benchmark::internal::Benchmark* b) {
  b->ArgNames({"family", "size"});
  for (int family = 0; family < 3; ++family)
    for (Index size : {10000, 100000}) b->Args({family, size});
}

// explicit:1 only without reconstruction (the A/B of the operator form).
void demand_variants(benchmark::internal::Benchmark* b) {
  b->ArgNames({"family", "size", "reconstruct", "design", "explicit"});
  for (int family = 0; family < 3; ++family)
    for (Index size : {10000, 100000})
      for (int r : {0, 1})
        for (int design : {0, 1})
          for (int ex : {0, 1})
            if (r == 0 || ex == 0) b->Args({family, size, r, design, ex});
}

void solve_variants(benchmark::internal::Benchmark* b) {
  b->ArgNames({"family", "size", "design", "explicit"});
  for (int family = 0; family < 3; ++family)
    for (Index size : {10000, 100000})
      for (int design : {0, 1})
        for (int ex : {0, 1}) b->Args({family, size, design, ex});
}

}  // namespace

BENCHMARK(BM_QpPrecompute)->Apply(families_and_sizes)->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(1);
BENCHMARK(BM_QpDemand)->Apply(demand_variants)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_QpSolve)->Apply(solve_variants)->Unit(benchmark::kMicrosecond)->UseRealTime();
BENCHMARK(BM_QpCachedSchur)->Apply(families_and_sizes)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_QpFullKkt)->Apply(families_and_sizes)->Unit(benchmark::kMillisecond)->UseRealTime();

BENCHMARK_MAIN();
