// Laplace / GMRF interpolation ("inpainting") on a grid, with the set of
// observed pixels changing per query — a non-graphics use of qpreduce.
//
// Model. An image x on an nx × ny grid with the smoothness prior ½xᵀHx, H the
// grid Laplacian (PSD, null space = constants), a linear "trend" term qᵀx with
// q = D·Y (D: low-order polynomials), and hard observations x_i = b_i at the
// observed pixels:  min ½xᵀHx − qᵀx  s.t.  Aᵀx = b,  A = selection.
// Every query observes a different subset of pixels, drawn from a fixed set
// of candidate sites (sensor locations). Design spaces: C = selection of the
// candidate sites (d of them), D = the trend basis (k columns).
//
// Part 1 (large grid): precompute once, then for every query compare the
// reduced path (set_constraints + solve + reconstruct) with a full sparse
// solve of the same query: time and d_H error (exact up to round-off, since
// A ∈ Span(C) and q ∈ Span(D)).
// Part 2 (small grid, dense analysis): observations partly OUTSIDE the
// candidate set, so A ∉ Span(C): the true d_H error against the Theorem 4.10
// bound (docs/theorem.md), per query.
//
// Usage: gmrf_inpainting [nx] [queries] [seed]   (defaults 400 20 1)
#include <qpreduce/problems/families.h>
#include <qpreduce/full_solve.h>
#include <qpreduce/theorem.h>
#include <qpreduce/subspace_solver.h>

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <string>
#include <vector>

using namespace qpreduce;
namespace fam = qpreduce::families;

namespace {

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0.0 : v[v.size() / 2];
}

int part1(Index nx, int queries, std::uint64_t seed) {
  const Index ny = nx, n = nx * ny, d = 300, k = 6, observed = 60;
  // The shared generator (families.h): grid Laplacian H, C = candidate sites, D = trend.
  const fam::QpFamily family = fam::make_gmrf({nx, ny, d, k, observed, 0.0, seed});
  const SparseMatrix<double>&H = family.H, &C = family.C, &D = family.D;

  fmt::print("Part 1: {}×{} grid (n = {}), {} candidate sites (d), {} trend columns (k), {} observed per query\n", nx,
             ny, n, d, k, observed);
  SubspaceSolver<double> solver;
  const SubspaceSummary s = solver.precompute(H, C, D);
  fmt::print("  precompute: {}\n", s.brief_report());
  if (!s.ok()) return 1;

  std::vector<double> t_op, t_solve, t_recon, t_full, err;
  Vector<double> w(solver.p()), X(n), X_full;
  for (int qi = 0; qi < queries; ++qi) {
    const fam::QpDemand q = fam::make_demand(family, static_cast<std::uint64_t>(qi));
    auto t0 = std::chrono::steady_clock::now();
    const ConstraintSummary cs = solver.set_constraints(q.A);
    t_op.push_back(seconds_since(t0));
    if (!cs.usable()) {
      fmt::print("  query {}: {}\n", qi, cs.message);
      return 1;
    }
    t0 = std::chrono::steady_clock::now();
    solver.solve_in_D(q.b, q.Y, w);
    t_solve.push_back(seconds_since(t0));
    t0 = std::chrono::steady_clock::now();
    solver.reconstruct(w, X);
    t_recon.push_back(seconds_since(t0));

    t0 = std::chrono::steady_clock::now();
    const FullSolveSummary fs = solve_full(H, q.A, q.b, q.q, &X_full);
    t_full.push_back(seconds_since(t0));
    if (!fs.ok()) {
      fmt::print("  query {}: full solve failed: {}\n", qi, fs.message);
      return 1;
    }
    err.push_back(h_distance(H, X, X_full) / std::max(1e-300, std::sqrt(X_full.dot(H * X_full))));
  }
  const double reduced = median(t_op) + median(t_solve) + median(t_recon);
  fmt::print("  median over {} queries:\n", queries);
  fmt::print("    set_constraints (OP)      {:10.3f} ms\n", 1e3 * median(t_op));
  fmt::print("    solve                     {:10.3f} µs\n", 1e6 * median(t_solve));
  fmt::print("    reconstruct (n values)    {:10.3f} ms\n", 1e3 * median(t_recon));
  fmt::print("    full sparse solve         {:10.3f} ms\n", 1e3 * median(t_full));
  fmt::print("    speed-up per query        {:10.1f}×  (full / (OP + solve + reconstruct))\n",
             median(t_full) / reduced);
  fmt::print("    relative d_H error        {:10.2e}   (max {:.2e}; A ∈ Span(C), q ∈ Span(D): exact up to round-off)\n",
             median(err), *std::max_element(err.begin(), err.end()));
  return *std::max_element(err.begin(), err.end()) < 1e-8 ? 0 : 1;
}

int part2(int queries, std::uint64_t seed) {
  const Index nx = 30, ny = 30, d = 80, k = 6, observed = 20;
  const fam::QpFamily family = fam::make_gmrf({nx, ny, d, k, observed, 0.0, seed + 7});
  const SparseMatrix<double>&H = family.H, &C = family.C, &D = family.D;
  fmt::print("\nPart 2: {}×{} grid, {} candidates, {} observed per query, some outside the candidates (A ∉ Span(C))\n",
             nx, ny, d, observed);
  TheoremChecker checker;
  const TheoremSetupSummary setup = checker.precompute(H, C, D);
  if (!setup.ok()) {
    fmt::print("  setup failed: {}\n", setup.message);
    return 1;
  }
  fmt::print("  {:>8} {:>12} {:>12} {:>10} {:>8}\n", "outside", "d_H error", "bound", "bound/err", "rho");
  int violations = 0;
  for (int qi = 0; qi < queries; ++qi) {
    const Index outside = qi % 4;  // 0, 1, 2, 3 observations off the candidate set
    const fam::QpDemand q = fam::make_demand(family, 500 + static_cast<std::uint64_t>(qi), {outside, 0.0});
    const TheoremCheck c = checker.check(q.A, q.b, q.q);
    if (c.practical_violation()) ++violations;
    fmt::print("  {:>8} {:>12.3e} {:>12.3e} {:>10.3g} {:>8.3f}\n", outside, c.practical_error, c.bound.bound,
               c.eta(), c.bound.rho);
  }
  fmt::print("  bound violations: {}\n", violations);
  return violations == 0 ? 0 : 1;
}

}  // namespace

int main(int argc, char** argv) {
  const Index nx = argc > 1 ? std::atol(argv[1]) : 400;
  const int queries = argc > 2 ? std::atoi(argv[2]) : 20;
  const std::uint64_t seed = argc > 3 ? static_cast<std::uint64_t>(std::atoll(argv[3])) : 1;
  if (nx < 20 || queries < 1) {
    fmt::print(stderr, "usage: gmrf_inpainting [nx ≥ 20] [queries ≥ 1] [seed]\n");
    return 2;
  }
  const int r1 = part1(nx, queries, seed);
  const int r2 = part2(std::max(queries, 8), seed);
  return r1 != 0 ? r1 : r2;
}
