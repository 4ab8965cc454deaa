// Builds against the installed reference and pipeline targets: runs the
// local-global full-space reference on a built-in shape, then the same
// handles as a two-frame scenario through run_scenario with a refine.
#include <qpreduce/deform/mesh/shapes.h>
#include <qpreduce/deform/pipeline/run_scenario.h>
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
  Scenario scenario;
  scenario.model = model;
  scenario.handles = handles;
  scenario.frames = {targets, targets};
  ScenarioRunOptions run;
  run.deformer.linear_proxies = 4;
  run.deformer.rotational_proxies = 4;
  run.refine = RefineOptions{};
  Deformer deformer;
  ScenarioPoses poses;
  const ScenarioRunSummary r = run_scenario(scenario, run, &deformer, &poses);
  std::printf("consumer: run_scenario %s, %zu frames, refined ARAP energy %.3e (reference %.3e)\n",
              r.brief_report().c_str(), r.frames.size(), r.arap_energy, s.energy);
  const bool run_ok = r.ok() && r.refined && r.refine.handle_residual < 1e-6 && r.arap_energy <= 1.0001 * s.energy + 1e-12;
  return s.ok() && s.handle_residual < 1e-6 && run_ok ? 0 : 1;
}
