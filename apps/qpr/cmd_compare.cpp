// `qpr compare MESH …`: the reduced deformation against full-space references
// (Ceres and/or local-global ARAP, reference.h) on the last frame of a
// scenario. No math here: the plugin solves, this file measures and reports.
#include "reports.h"
#include "commands.h"
#include "deform_run.h"
#include "guard.h"
#include "refine_run.h"
#include "validators.h"

#include <qpreduce/deform/mesh/geometry.h>
#include <qpreduce/deform/reference/reference.h>

#include <CLI/CLI.hpp>
#include <fmt/format.h>

#include <cmath>
#include <filesystem>
#include <memory>

namespace qpr {

namespace {

using namespace qpreduce;
using namespace qpreduce::deform;

struct CompareArgs : ScenarioArgs {
  std::string reference = "both";  // ceres | local-global | both
  std::string energy = "classic";  // classic | modified
  int reference_iterations = 20000;
  std::string out_dir = "qpr-compare", report;
  bool convergence = false;
  double convergence_tolerance = 1e-10, gap = 1e-4;
  int anderson_window = 5;
};

nlohmann::json deviation(const Vertices& a, const Vertices& b, double diag) {
  const Eigen::VectorXd d = (a - b).rowwise().norm();
  return {{"rms_deviation", std::sqrt(d.squaredNorm() / static_cast<double>(d.size())) / diag},
          {"max_deviation", d.maxCoeff() / diag}};
}

// Where the meshes of the comparison go: <out_dir>/<what>.<ext>, with an
// extension the loaded mesh can be written as.
struct OutputPaths {
  std::string dir, ext;
  std::string operator()(const std::string& what) const {
    return (std::filesystem::path(dir) / (what + "." + ext)).string();
  }
};

// The reduced run's part of the report: its energy and residual on the last
// frame, and the run's settings and times.
nlohmann::json reduced_json(const Scenario& sc, const RotationElements& elements, const RunOutputs& reduced,
                            const nlohmann::json& rep, double diag) {
  nlohmann::json red;
  red["arap_energy"] = arap_energy(sc.model.V, elements, reduced.last);
  red["handle_residual"] = handle_residual(sc, sc.frames.back(), reduced.last) / diag;
  red["frame_ms"] = rep["frame_ms"];
  red["precompute_s"] = rep["precompute_s"];
  red["linear_proxies"] = rep["linear_proxies"];
  red["rotational_proxies"] = rep["rotational_proxies"];
  red["iterations"] = rep["iterations"];
  red["frames"] = rep["frames"];
  red["alpha"] = rep["alpha"];
  red["beta"] = rep["beta"];
  return red;
}

// One reference solve of the last frame (`which`: "ceres" or "local-global"),
// reported; its pose is written and compared with the reduced one when it succeeds.
nlohmann::json reference_json(const std::string& which, const DeformableMesh& model, const LoadedScenario& ls,
                              const ReferenceOptions& ro, const RotationElements& elements, const RunOutputs& reduced,
                              const OutputPaths& path, double diag) {
  const Scenario& sc = ls.scenario;
  ReferenceSolution sol;
  const ReferenceSummary s = which == "ceres" ? solve_ceres_reference(model, sc.handles, sc.frames.back(), ro, &sol)
                                              : solve_local_global(model, sc.handles, sc.frames.back(), ro, &sol);
  nlohmann::json r;
  r["status"] = to_string(s.status);
  r["message"] = s.message;
  r["converged"] = s.converged;
  r["iterations"] = s.iterations;
  r["energy_kind"] = to_string(s.energy_kind);
  r["energy"] = s.energy;
  r["arap_energy"] = arap_energy(sc.model.V, elements, sol.V);
  r["handle_residual"] = s.handle_residual / diag;
  r["setup_ms"] = 1e3 * s.setup_seconds;
  r["solve_ms"] = 1e3 * s.solve_seconds;
  if (!s.ok()) {
    std::fprintf(stderr, "  %s reference failed: %s\n", which.c_str(), s.message.c_str());
    return r;
  }
  const std::string file = path("reference_" + which);
  write_pose(run_files().stage(file), sol.V, ls.tet ? nullptr : &ls.surface, ls.tet ? &ls.solid : nullptr);
  r["mesh"] = file;
  r.update(deviation(reduced.last, sol.V, diag));
  return r;
}

// The comparison table (stdout).
void print_comparison(const CompareArgs& a, const std::string& primary, const nlohmann::json& report,
                      const nlohmann::json& refs, int reduced_rounds) {
  const nlohmann::json& red = report["reduced"];
  fmt::print("compare ({} energy), reference = {}:\n", a.energy, primary);
  fmt::print("  {:<14}{:>14}{:>14}{:>12}{:>12}{:>14}{:>12}\n", "", "ARAP energy", "handle res.", "RMS dev.", "max dev.",
             "time ms", "iterations");
  fmt::print("  {:<14}{:>14.6g}{:>14.2e}{:>12}{:>12}{:>14.3f}{:>12}\n", "reduced", red["arap_energy"].get<double>(),
             red["handle_residual"].get<double>(), "", "", red["frame_ms"].get<double>(), reduced_rounds);
  for (const auto& [which, r] : refs.items()) {
    if (!r.contains("rms_deviation")) continue;
    fmt::print("  {:<14}{:>14.6g}{:>14.2e}{:>11.2f}%{:>11.2f}%{:>14.1f}{:>12}{}\n", which, r["arap_energy"].get<double>(),
               r["handle_residual"].get<double>(), 100 * r["rms_deviation"].get<double>(),
               100 * r["max_deviation"].get<double>(), r["solve_ms"].get<double>(), r["iterations"].get<int>(),
               r["converged"].get<bool>() ? "" : "  (not converged)");
  }
  fmt::print("  energy ratio {:.3f}, speedup {:.0f}x (one reference solve / one reduced frame); meshes in {}\n",
             report["energy_ratio"].get<double>(), report["speedup"].get<double>(), a.out_dir);
}

// Throws std::invalid_argument for a value outside its choices, or an
// unwritable report path, before any work.
void check_compare_args(const CompareArgs& a) {
  if (a.reference != "ceres" && a.reference != "local-global" && a.reference != "both" && a.reference != "none")
    throw std::invalid_argument("--reference must be ceres, local-global, both or none, got " + a.reference);
  if (a.reference == "none" && !a.convergence) throw std::invalid_argument("--reference none needs --convergence");
  if (a.energy != "classic" && a.energy != "modified")
    throw std::invalid_argument("--energy must be classic or modified, got " + a.energy);
  if (!a.report.empty()) qpreduce::check_destination(a.report, "report");
}

// Full-space classic ARAP from the reduced rounds' fixed point at the last
// frame (the hands stop, as `qpr deform --refine`) and from rest, plain and
// accelerated, each to the relative energy change or fixed-point residual
// --convergence-tolerance (no distance test: these runs measure it).
nlohmann::json run_convergence_study(const CompareArgs& a, const Scenario& sc, const Vertices& settled) {
  RefineArgs ra;
  ra.anderson_window = a.anderson_window;
  RefineOptions o = refine_options(ra);
  o.distance_tolerance = 0.0;
  o.tolerance = a.convergence_tolerance;
  o.max_iterations = a.reference_iterations;
  return convergence_study(sc, settled, o, a.gap);
}

int run_compare(const CompareArgs& a) {
  check_compare_args(a);
  LoadedScenario ls = load_scenario(a);
  const OutputPaths path{a.out_dir, ls.tet ? (ls.solid.F.rows() > 0 ? "off" : "mesh") : "off"};
  run_files().create_directories(a.out_dir);

  // The reduced run (every frame, as `qpr deform`), keeping the last pose.
  RunSettings settings;
  settings.name = ls.name;
  settings.run.deformer = ls.options;
  settings.out_path = path("reduced");
  settings.preflight = ls.preflight;
  settings.run.settle = a.convergence;  // the convergence study starts from the settled pose
  RunOutputs reduced;
  const nlohmann::json rep = run_scenario(ls.scenario, ls.tet ? nullptr : &ls.surface, ls.tet ? &ls.solid : nullptr,
                                          settings, &reduced);
  const Scenario& sc = ls.scenario;
  const double diag = bounding_box_diagonal(sc.model.V);

  // The references, on the last frame's targets, from the rest pose.
  ReferenceOptions ro;
  ro.max_iterations = a.reference_iterations;
  DeformableMesh model = sc.model;
  if (a.energy == "modified") {
    // E′ with the reduced run's clusters, α, β and last global rotation r₀.
    ro.energy = ReferenceEnergy::ModifiedArap;
    ro.parameters = reduced.options.energy;
    ro.frame = reduced.global_rotation;
    model.clusters = reduced.clusters;
  }
  const RotationElements elements =
      ls.tet ? tet_elements(sc.model.V, sc.model.T) : spokes_and_rims_elements(sc.model.V, sc.model.F);
  nlohmann::json report;
  report["name"] = ls.name;
  report["vertices"] = sc.model.V.rows();
  report["bounding_box_diagonal"] = diag;
  report["energy"] = a.energy;
  report["reduced"] = reduced_json(sc, elements, reduced, rep, diag);

  nlohmann::json refs = nlohmann::json::object();
  std::string primary;
  for (const std::string which : {"ceres", "local-global"}) {
    if (a.reference != "both" && a.reference != which) continue;
    refs[which] = reference_json(which, model, ls, ro, elements, reduced, path, diag);
    if (!refs[which].contains("mesh")) continue;  // failed
    // The primary reference: Ceres when it converged, else local-global.
    if (primary.empty() || (which == "local-global" && !refs[primary]["converged"].get<bool>())) primary = which;
  }
  report["references"] = refs;
  if (a.convergence) {
    report["convergence"] = run_convergence_study(a, sc, reduced.settled);
    report["convergence"]["settle"] = rep["settle"];
  }
  if (a.reference == "none") {
    if (!a.report.empty()) write_json(run_files().stage(a.report), report);
    return 0;
  }
  if (primary.empty()) throw std::runtime_error("no reference succeeded");
  const nlohmann::json& ref = refs[primary];
  report["reference"] = ref;
  report["reference"]["solver"] = primary;
  report["energy_ratio"] = report["reduced"]["arap_energy"].get<double>() / ref["arap_energy"].get<double>();
  report["rms_deviation"] = ref["rms_deviation"];
  report["max_deviation"] = ref["max_deviation"];
  report["speedup"] = ref["solve_ms"].get<double>() / report["reduced"]["frame_ms"].get<double>();

  print_comparison(a, primary, report, refs, rep["rounds"].get<int>());
  if (!a.report.empty()) write_json(run_files().stage(a.report), report);
  return 0;
}

}  // namespace

void register_compare(CLI::App& app) {
  auto [cmd, a] = add_command<CompareArgs>(app, "compare", "Reduced ARAP against full-space references (Ceres, local-global)");
  add_scenario_options(cmd, a.get());
  cmd->add_option("--reference", a->reference, "ceres, local-global, both (default) or none (with --convergence)");
  cmd->add_option("--energy", a->energy,
                  "classic: references minimise classic ARAP (default); modified: the reduced model's E' with its "
                  "clusters, alpha, beta and global rotation");
  cmd->add_option("--reference-iterations", a->reference_iterations, "Iteration limit of the references")
      ->check(whole_number_between(1, 10000000));
  cmd->add_flag("--convergence", a->convergence,
                "Also report rounds and seconds of full-space classic ARAP from the reduced pose and from rest, "
                "plain and Anderson-accelerated (the report's \"convergence\")");
  cmd->add_option("--convergence-tolerance", a->convergence_tolerance,
                  "--convergence: stop each run at this relative energy change or fixed-point residual (default "
                  "1e-10; at most --reference-iterations rounds)")
      ->check(number_between(0.0, 1.0));
  cmd->add_option("--gap", a->gap,
                  "--convergence: also time each run to this relative energy gap to the lowest energy reached "
                  "(default 1e-4)")
      ->check(number_above(0.0, 1.0));
  cmd->add_option("--refine-anderson", a->anderson_window, "--convergence: Anderson window, 1-16 (default 5)")
      ->check(whole_number_between(1, 16));
  add_path_option(cmd, PathRole::OutputDirectory, "--out-dir", a->out_dir, "Directory for the meshes compared (default qpr-compare)");
  add_path_option(cmd, PathRole::Output, "--report", a->report, "JSON report");
  cmd->callback([a = a]() { run_guarded("compare", [&] { return run_compare(*a); }); });
}

}  // namespace qpr
