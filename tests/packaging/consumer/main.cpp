// Builds against the installed headers and libraries without Ceres: solves
// one tiny demand with the engine, and deforms a built-in shape.
#include <qpreduce/deform/deformer/deformer.h>
#include <qpreduce/deform/mesh/shapes.h>
#include <qpreduce/problems/generators.h>
#include <qpreduce/subspace_solver.h>

#include <cmath>
#include <cstdio>

namespace {

int engine_demand() {
  using namespace qpreduce;
  const SparseMatrix<double> H = generators::grid_laplacian_2d(10, 10);
  const SparseMatrix<double> C = generators::selection(100, {0, 45, 99});
  const SparseMatrix<double> D = generators::grid_trend_basis(10, 10, 2);
  SubspaceSolver<double> solver;
  const SubspaceSummary s = solver.precompute(H, C, D);
  if (!s.ok()) {
    std::fprintf(stderr, "consumer: %s\n", s.brief_report().c_str());
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
  std::printf("consumer: engine OK (constraint error %.2e)\n", err);
  return err < 1e-10 ? 0 : 1;
}

int deformer_frame() {
  using namespace qpreduce::deform;
  const TriangleMesh mesh = shapes::capped_cylinder(0.5, 2.0, 12, 8);
  DeformableMesh model;
  model.V = mesh.V;
  model.F = mesh.F;
  DeformerOptions options;
  options.rotational_proxies = 4;
  options.linear_proxies = 4;
  Deformer deformer;
  if (!deformer.precompute(model, options).ok()) return 1;
  Handles handles;
  handles.points = {PointHandle{{0}, {}}, PointHandle{{model.V.rows() - 1}, {}}};
  if (!deformer.set_handles(handles).ok()) return 1;
  HandleTargets targets;
  targets.points.resize(2, 3);
  targets.points.row(0) = model.V.row(0);
  targets.points.row(1) = model.V.row(model.V.rows() - 1) + Eigen::RowVector3d(0.1, 0.0, 0.0);
  Vertices out;
  deformer.frame(targets, &out);
  const double err = (out.row(0) - targets.points.row(0)).norm();
  std::printf("consumer: deformer OK (handle error %.2e)\n", err);
  return out.allFinite() && err < 1e-4 ? 0 : 1;
}

}  // namespace

int main() { return engine_demand() + deformer_frame(); }
