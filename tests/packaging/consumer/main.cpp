// Builds against the installed headers and library; solves one tiny demand.
#include <qpreduce/generators.h>
#include <qpreduce/subspace_solver.h>

#include <cstdio>

int main() {
  using namespace qpreduce;
  const SparseMatrix<double> H = generators::grid_laplacian_2d(10, 10);
  const SparseMatrix<double> C = generators::selection(100, {0, 45, 99});
  const SparseMatrix<double> D = generators::grid_trend_basis(10, 10, 2);
  SubspaceSolver<double> solver;
  const SubspaceSummary s = solver.precompute(H, C, D);
  if (!s.ok()) {
    std::fprintf(stderr, "consumer: %s\n", s.report().c_str());
    return 1;
  }
  if (!solver.set_constraints(C).ok()) return 1;
  Vector<double> b(3), Y(2), w(solver.p()), X(100);
  b << 1.0, 2.0, 3.0;
  Y << 0.0, 0.0;
  solver.solve_in_D(b, Y, w);
  solver.reconstruct(w, X);
  // Hard constraints hold exactly (up to round-off) at the selected vertices.
  const double err = std::abs(X(0) - 1.0) + std::abs(X(45) - 2.0) + std::abs(X(99) - 3.0);
  std::printf("consumer: qpreduce package OK (constraint error %.2e)\n", err);
  return err < 1e-10 ? 0 : 1;
}
