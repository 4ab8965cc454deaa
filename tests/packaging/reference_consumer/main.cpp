// Builds against the installed reference target: runs the local-global
// full-space reference on a built-in shape.
#include <qpreduce/deform/mesh/shapes.h>
#include <qpreduce/deform/reference/reference.h>

#include <cstdio>

int main() {
  using namespace qpreduce::deform;
  const TriangleMesh mesh = shapes::capped_cylinder(0.5, 2.0, 12, 8);
  DeformableMesh model;
  model.V = mesh.V;
  model.F = mesh.F;
  Handles handles;
  handles.points = {PointHandle{{0}, {}}, PointHandle{{model.V.rows() - 1}, {}}};
  HandleTargets targets;
  targets.points.resize(2, 3);
  targets.points.row(0) = model.V.row(0);
  targets.points.row(1) = model.V.row(model.V.rows() - 1) + Eigen::RowVector3d(0.1, 0.0, 0.0);
  ReferenceSolution solution;
  const ReferenceSummary s = solve_local_global(model, handles, targets, ReferenceOptions{}, &solution);
  std::printf("consumer: reference %s, handle residual %.2e, Ceres %s\n", s.message.c_str(), s.handle_residual,
              has_ceres_reference() ? "available" : "not built");
  return s.ok() && s.handle_residual < 1e-6 ? 0 : 1;
}
