// `qpr demo`: a built-in capped cylinder (the size of the Botsch–Sorkine one,
// 4,802 vertices) with its base fixed and its top cap as an affine handle,
// bent by 90° and twisted by 90° over a few frames. No files needed.
#include "commands.h"
#include "deform_run.h"
#include "guard.h"
#include "validators.h"

#include <qpreduce/deform/io/mesh_io.h>
#include <qpreduce/deform/mesh/shapes.h>

#include <CLI/CLI.hpp>
#include <Eigen/Geometry>
#include <fmt/format.h>

#include <cmath>
#include <optional>
#include <filesystem>
#include <memory>

namespace qpr {

namespace {

struct DemoArgs {
  int frames = 12;
  std::string out_dir = "qpr-demo";
  std::string report;
  std::optional<int> iterations;  // unset: DeformerOptions' default
  long rotational = 27, linear = 33;
};

int run_demo(const DemoArgs& a) {
  using namespace qpreduce;
  using namespace qpreduce::deform;
  const double radius = 1.0, height = 12.0, pi = std::acos(-1.0);
  const TriangleMesh mesh = shapes::capped_cylinder(radius, height, 60, 80);
  Selection sel;
  sel.roles.assign(static_cast<size_t>(mesh.V.rows()), SelRole::Free);
  for (Index v = 0; v < mesh.V.rows(); ++v) {
    if (mesh.V(v, 2) < 0.6) sel.roles[v] = SelRole::Fixed;
    if (mesh.V(v, 2) > height - 0.6) sel.roles[v] = SelRole::Handle;
  }
  Scenario sc = scenario_from_sel_def(mesh.V, sel, Eigen::Matrix4d::Identity(), 1);
  sc.model.F = mesh.F;
  // Frame f: the top cap rotated by Rx(θ)·Rz(φ) about its centre and carried
  // along the arc a 12-long rod bent by θ would follow.
  sc.frames.clear();
  const Eigen::Vector3d centre(0, 0, height);
  for (int f = 1; f <= a.frames; ++f) {
    const double t = static_cast<double>(f) / a.frames, theta = t * pi / 2, phi = t * pi / 2;
    const Eigen::Matrix3d R = (Eigen::AngleAxisd(theta, Eigen::Vector3d::UnitX()) *
                               Eigen::AngleAxisd(phi, Eigen::Vector3d::UnitZ())).toRotationMatrix();
    // Arc of a rod of length `height` bent uniformly by θ: tip at
    // (0, −(1 − cos θ)·ℓ/θ, sin θ·ℓ/θ).
    const double l_over_theta = height / theta;
    const Eigen::Vector3d arc(0.0, -(1 - std::cos(theta)) * l_over_theta, std::sin(theta) * l_over_theta);
    Eigen::Matrix<double, 3, 4> T;
    T.leftCols<3>() = R;
    T.col(3) = arc - R * centre;
    HandleTargets targets;
    targets.points.resize(0, 3);
    targets.patch_transforms = {T};
    sc.frames.push_back(targets);
  }
  run_files().create_directories(a.out_dir);
  RunSettings settings;
  settings.name = "demo (built-in capped cylinder, bend 90° + twist 90°)";
  if (a.iterations) settings.run.deformer.iterations = *a.iterations;
  settings.run.deformer.rotational_proxies = a.rotational;
  settings.run.deformer.linear_proxies = a.linear;
  settings.out_path = a.out_dir + "/cylinder_{frame}.off";
  settings.write_frames.clear();
  for (int f = 0; f < a.frames; f += std::max(1, a.frames / 4)) settings.write_frames.push_back(f);
  settings.write_frames.push_back(a.frames - 1);
  settings.report_path = a.report.empty() ? a.out_dir + "/report.json" : a.report;
  check_outputs(settings);
  write_triangle_mesh(run_files().stage(a.out_dir + "/cylinder_rest.off"), mesh);
  run_scenario(sc, &mesh, nullptr, settings);
  fmt::print("  meshes and report.json written to {}/\n", a.out_dir);
  return 0;
}

}  // namespace

void register_demo(CLI::App& app) {
  auto [cmd, args] = add_command<DemoArgs>(app, "demo", "Bend and twist a built-in cylinder with reduced ARAP (no files needed)");
  cmd->add_option("--frames", args->frames, "Frames from rest to the full bend")->check(whole_number_between(1, 10000));
  add_path_option(cmd, PathRole::OutputDirectory, "--out", args->out_dir, "Output folder for the meshes and the report");
  add_path_option(cmd, PathRole::Output, "--report", args->report, "JSON report path (default OUT/report.json)");
  const qpreduce::deform::DeformerOptions defaults;
  cmd->add_option("--iterations", args->iterations,
                  fmt::format("Phase 1/Phase 2 rounds per frame: the cap (default {}; the rounds stop at a "
                              "fixed-point residual of {:g} or after {:g} ms)",
                              defaults.iterations, defaults.tolerance, 1e3 * defaults.time_budget))
      ->check(whole_number_between(1, 1000));
  cmd->add_option("--rotational-proxies", args->rotational, "Rotational clusters")
      ->check(whole_number_between(1, 100000));
  cmd->add_option("--linear-proxies", args->linear, "Linear proxies (farthest-point samples)")
      ->check(whole_number_between(1, 100000));
  cmd->callback([args = args]() { run_guarded("demo", [&] { return run_demo(*args); }); });
}

}  // namespace qpr
