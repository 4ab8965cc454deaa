// Benchmark: the per-demand work of the reduced solver against a full sparse
// solve of the same demand (Eq. 1), on 2-D grid Laplacians with p = d + k =
// 300 (290 selected vertices, 10 trend columns) and m = 30 point handles at
// C vertices, so the reduced answer is exact and the two can be compared.
//
//   BM_SetConstraints   the on-site step ("OP"): A_r = AᵀB and the small dense
//                       solution operators M_b, M_q, M_Y;
//   BM_Solve            w = M_b·b + M_q·q_r (general linear term, reduced);
//   BM_SolveInD         w = M_b·b + M_Y·Y (q = D·Y);
//   BM_PerDemand        set_constraints + solve_in_D: a new demand end to end
//                       in reduced coordinates;
//   BM_ReduceLinearTerm q_r = Bᵀq for a general q (O(n·p));
//   BM_Reconstruct      X = N·z + UD·y (O(n·p));
//   BM_FullSolve        qpreduce::solve_full on the same demand: variant 0
//                       default options, 1 without the PSD check and the
//                       residual (the lean reference), 2 SparseLU of the
//                       KKT matrix (lean).
// The subspace precompute is set-up here (cached per size across
// benchmarks); it is timed by bench_subspace.
#include "bench_util.h"

#include "qpreduce/full_solve.h"
#include "qpreduce/subspace_solver.h"

#include <benchmark/benchmark.h>

#include <map>
#include <memory>

namespace {

using namespace qpreduce;
using qpreduce::bench::DKind;

constexpr Index kP = 300, kM = 30;

template <typename Scalar>
struct Fixture {
  bench::GridProblem g;
  SubspaceSolver<Scalar> solver;
  Vector<double> X_reduced;  // reduced answer of the demand, for the full-solve comparison
  Status status = Status::NotRun;  // of set_constraints on the demand
};

// Precomputed solvers, one per (size, scalar), built on first use.
template <typename Scalar>
Fixture<Scalar>& fixture(Index side) {
  static std::map<Index, std::unique_ptr<Fixture<Scalar>>> cache;
  auto& slot = cache[side];
  if (!slot) {
    slot = std::make_unique<Fixture<Scalar>>();
    Fixture<Scalar>& f = *slot;
    f.g = bench::make_grid_problem(side, kP, DKind::Trend, kM);
    const SubspaceSummary s = f.solver.precompute(f.g.H.template cast<Scalar>(), f.g.C.template cast<Scalar>(),
                                                  f.g.D.template cast<Scalar>());
    if (!s.ok()) throw std::runtime_error(s.brief_report());
    // Any status with an answer is timed; the label says which one it was.
    f.status = f.solver.set_constraints(f.g.A.template cast<Scalar>()).status;
    if (f.status == Status::NotRun) throw std::runtime_error("set_constraints did not run");
    Vector<Scalar> w(f.solver.p()), X(f.solver.n());
    f.solver.solve_in_D(f.g.b.template cast<Scalar>(), f.g.Y.template cast<Scalar>(), w);
    f.solver.reconstruct(w, X);
    f.X_reduced = X.template cast<double>();
  }
  return *slot;
}

void common_counters(benchmark::State& state, const bench::GridProblem& g) {
  state.counters["n"] = static_cast<double>(g.n);
  state.counters["p"] = static_cast<double>(g.d + g.k);
  state.counters["m"] = static_cast<double>(g.m);
}

// Second argument: 1 the default (fast path), 0 the O(p³) null-space method
// (what set_constraints did before the fast path).
void BM_SetConstraints(benchmark::State& state) {
  auto& f = fixture<double>(state.range(0));
  const SparseMatrix<double> A = f.g.A;
  ConstraintOptions opts;
  opts.fast_path = state.range(1) != 0;
  ConstraintSummary cs;
  for (auto _ : state) {
    cs = f.solver.set_constraints(A, opts);
    benchmark::DoNotOptimize(&cs);
  }
  common_counters(state, f.g);
  state.counters["rank"] = static_cast<double>(cs.rank);
  state.SetLabel(std::string(to_string(cs.status)) + (cs.fast_path ? "/fast-path" : "/null-space"));
  f.solver.set_constraints(A);  // leave the default operators for the other benchmarks
}

template <typename Scalar>
void BM_Solve(benchmark::State& state) {
  auto& f = fixture<Scalar>(state.range(0));
  f.solver.set_constraints(f.g.A.template cast<Scalar>());
  const Vector<Scalar> b = f.g.b.template cast<Scalar>();
  Vector<Scalar> q_r(f.solver.p()), w(f.solver.p());
  f.solver.reduce_linear_term(f.g.q.template cast<Scalar>(), q_r);
  for (auto _ : state) {
    f.solver.solve(b, q_r, w);
    benchmark::DoNotOptimize(w.data());
    benchmark::ClobberMemory();
  }
  common_counters(state, f.g);
}

template <typename Scalar>
void BM_SolveInD(benchmark::State& state) {
  auto& f = fixture<Scalar>(state.range(0));
  f.solver.set_constraints(f.g.A.template cast<Scalar>());
  const Vector<Scalar> b = f.g.b.template cast<Scalar>(), Y = f.g.Y.template cast<Scalar>();
  Vector<Scalar> w(f.solver.p());
  for (auto _ : state) {
    f.solver.solve_in_D(b, Y, w);
    benchmark::DoNotOptimize(w.data());
    benchmark::ClobberMemory();
  }
  common_counters(state, f.g);
}

void BM_PerDemand(benchmark::State& state) {
  auto& f = fixture<double>(state.range(0));
  const SparseMatrix<double> A = f.g.A;
  Vector<double> w(f.solver.p());
  for (auto _ : state) {
    f.solver.set_constraints(A);
    f.solver.solve_in_D(f.g.b, f.g.Y, w);
    benchmark::DoNotOptimize(w.data());
    benchmark::ClobberMemory();
  }
  common_counters(state, f.g);
}

template <typename Scalar>
void BM_ReduceLinearTerm(benchmark::State& state) {
  auto& f = fixture<Scalar>(state.range(0));
  const Vector<Scalar> q = f.g.q.template cast<Scalar>();
  Vector<Scalar> q_r(f.solver.p());
  for (auto _ : state) {
    f.solver.reduce_linear_term(q, q_r);
    benchmark::DoNotOptimize(q_r.data());
    benchmark::ClobberMemory();
  }
  common_counters(state, f.g);
}

template <typename Scalar>
void BM_Reconstruct(benchmark::State& state) {
  auto& f = fixture<Scalar>(state.range(0));
  f.solver.set_constraints(f.g.A.template cast<Scalar>());
  Vector<Scalar> w(f.solver.p()), X(f.solver.n());
  f.solver.solve_in_D(f.g.b.template cast<Scalar>(), f.g.Y.template cast<Scalar>(), w);
  for (auto _ : state) {
    f.solver.reconstruct(w, X);
    benchmark::DoNotOptimize(X.data());
    benchmark::ClobberMemory();
  }
  common_counters(state, f.g);
}

void BM_FullSolve(benchmark::State& state) {
  const int variant = static_cast<int>(state.range(1));
  // The reference answer needs the reduced solver only once; the full solve
  // itself uses nothing precomputed.
  const auto& f = fixture<double>(state.range(0));
  const bench::GridProblem& g = f.g;
  SubspaceOptions opts;
  if (variant >= 1) {
    opts.check_psd = false;
    opts.compute_residual = false;
  }
  if (variant == 2) opts.backend = Backend::SparseLU;
  Vector<double> X;
  FullSolveSummary s;
  for (auto _ : state) {
    s = solve_full(g.H, g.A, g.b, g.q, &X, opts);
    benchmark::DoNotOptimize(X.data());
  }
  if (!s.ok()) {
    state.SkipWithError(s.message.c_str());
    return;
  }
  common_counters(state, g);
  // Relative difference to the reduced answer: the demand lies in the design
  // spaces, so both solve Eq. 1 exactly.
  state.counters["rel_diff"] = (X - f.X_reduced).norm() / f.X_reduced.norm();
  static const char* names[] = {"default", "lean", "sparse-lu-kkt"};
  state.SetLabel(std::string(names[variant]) + "/" + to_string(s.backend_used));
}

void Sides(benchmark::internal::Benchmark* b) {
  for (int side : {100, 200, 300, 400, 500}) b->Arg(side);
}

void ConstraintSizes(benchmark::internal::Benchmark* b) {
  for (int side : {100, 200, 300, 400, 500})
    for (int fast : {1, 0}) b->Args({side, fast});
}

void FullSizes(benchmark::internal::Benchmark* b) {
  for (int side : {100, 200, 300, 400, 500})
    for (int variant : {0, 1, 2}) b->Args({side, variant});
}

}  // namespace

BENCHMARK(BM_SetConstraints)
    ->ArgNames({"side", "fast"})
    ->Apply(ConstraintSizes)
    ->Unit(benchmark::kMicrosecond)
    ->UseRealTime();
BENCHMARK_TEMPLATE(BM_Solve, double)->ArgName("side")->Apply(Sides)->Unit(benchmark::kMicrosecond);
BENCHMARK_TEMPLATE(BM_Solve, float)->ArgName("side")->Apply(Sides)->Unit(benchmark::kMicrosecond);
BENCHMARK_TEMPLATE(BM_SolveInD, double)->ArgName("side")->Apply(Sides)->Unit(benchmark::kMicrosecond);
BENCHMARK_TEMPLATE(BM_SolveInD, float)->ArgName("side")->Apply(Sides)->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_PerDemand)->ArgName("side")->Apply(Sides)->Unit(benchmark::kMicrosecond)->UseRealTime();
BENCHMARK_TEMPLATE(BM_ReduceLinearTerm, double)->ArgName("side")->Apply(Sides)->Unit(benchmark::kMicrosecond)->UseRealTime();
BENCHMARK_TEMPLATE(BM_ReduceLinearTerm, float)->ArgName("side")->Apply(Sides)->Unit(benchmark::kMicrosecond)->UseRealTime();
BENCHMARK_TEMPLATE(BM_Reconstruct, double)->ArgName("side")->Apply(Sides)->Unit(benchmark::kMicrosecond)->UseRealTime();
BENCHMARK_TEMPLATE(BM_Reconstruct, float)->ArgName("side")->Apply(Sides)->Unit(benchmark::kMicrosecond)->UseRealTime();
BENCHMARK(BM_FullSolve)
    ->ArgNames({"side", "variant"})
    ->Apply(FullSizes)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

BENCHMARK_MAIN();
