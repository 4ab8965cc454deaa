// qpr — loading and running a deformation scenario and reporting it (shared
// by `qpr demo`, `qpr deform` and `qpr compare`). No math here: the plugin
// does the work, this file parses the inputs, times the run, prints the table
// and writes the meshes and the JSON report.
#pragma once

#include <qpreduce/util/atomic_file.h>
#include <qpreduce/deform/io/scenario.h>
#include <qpreduce/deform/pipeline/run_scenario.h>

#include <nlohmann/json.hpp>

#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace CLI {
class App;
}

namespace qpr {

// The inputs of a deformation: mesh, one handle source, proxies, energy
// (the options of `qpr deform` and `qpr compare`).
struct ScenarioArgs {
  std::string mesh, sel, def, anim, scene;
  long linear_proxies = 0, rotational_proxies = 0;
  std::string linear_groups, rotational_clusters, affine_patches;
  std::optional<int> iterations;  // unset: DeformerOptions' default
  int frames = 1;
  std::optional<double> alpha, beta, gamma, psi, soft;
  std::string model;  // "", "arap" or "conformal"
  std::string rotation_step = "exact";  // "exact" or "paper"
  std::optional<double> tolerance, time_budget_ms;  // unset: DeformerOptions' defaults
  std::optional<int> cold_start_rounds;  // unset: DeformerOptions' default
  std::optional<int> anderson_window;  // unset: DeformerOptions' default with exact, 0 with paper
  bool no_second_order = false;        // DeformerOptions::second_order = false
  bool exact_unreachable = false;      // DeformerOptions::soften_unreachable_handles = false
  bool exact_handles = false;          // point-handle vertices as linear proxies (exact_handle_proxies)
  bool double_basis = false;           // DeformerOptions::double_basis
};

// Registers the ScenarioArgs options (and the MESH positional) on `cmd`.
void add_scenario_options(CLI::App* cmd, ScenarioArgs* args);

// The scenario, its mesh and the deformer options the arguments ask for.
struct LoadedScenario {
  qpreduce::deform::Scenario scenario;
  qpreduce::deform::TriangleMesh surface;  // when !tet
  qpreduce::deform::TetMesh solid;         // when tet
  bool tet = false;
  qpreduce::deform::DeformerOptions options;
  std::string name;
  nlohmann::json preflight;  // the mesh pre-flight's findings (preflight.h)
};
// Reads the files, builds the scenario and runs the mesh pre-flight
// (preflight.h; `strict`: its warnings are errors). Throws on bad input.
LoadedScenario load_scenario(const ScenarioArgs& args, bool strict = false);

// Writes a pose of the loaded mesh: surfaces as OBJ/OFF/PLY; tets as .mesh,
// .node/.ele, or their boundary surface for a surface extension.
void write_pose(const std::string& path, const qpreduce::deform::Vertices& V,
                const qpreduce::deform::TriangleMesh* surface, const qpreduce::deform::TetMesh* solid);

// What a run leaves behind besides the report: the last frame's pose and the
// deformer's clusters and rotations (for comparisons).
struct RunOutputs {
  qpreduce::deform::Vertices last;
  qpreduce::deform::Vertices settled;      // RunSettings::settle or refine: the last frame's fixed point
  std::vector<int> clusters;               // per rotation element
  Eigen::VectorXd rotations;               // S, 9d
  Eigen::Matrix3d global_rotation = Eigen::Matrix3d::Identity();  // r₀ of the last frame
  qpreduce::deform::DeformerOptions options;  // as used (scene overrides applied)
};

struct RunSettings {
  // What runs (qpreduce::deform::run_scenario): the deformer's options, the
  // cache (loaded when it holds a matching model, else written after the
  // precompute), strict handles, settle and refine (with refine, the mesh
  // written and arap_energy are the refined pose's).
  qpreduce::deform::ScenarioRunOptions run;
  // Meshes written: every frame in `write_frames` (0-based; −1 = the last).
  std::vector<int> write_frames{-1};
  std::string out_path;     // the last frame's mesh (or a pattern with {frame})
  std::string report_path;  // JSON report, optional
  bool progress = true;     // progress bar on stderr during precompute
  std::string name;         // what is deformed, for the table
  nlohmann::json preflight;  // set: the report's "preflight" (LoadedScenario::preflight)
};

// Checks, before anything runs or is written, that the mesh, the report and
// the cache can be written where the settings say (qpreduce::check_destination);
// throws qpreduce::FileError naming the output otherwise.
inline void check_outputs(const RunSettings& settings) {
  for (const auto& [path, what] :
       {std::pair{&settings.out_path, "mesh"}, {&settings.report_path, "report"}, {&settings.run.cache_path, "cache"}})
    if (!path->empty()) qpreduce::check_destination(*path, what);
}

// Precomputes, sets the handles, runs every frame of the scenario, prints a
// timing table to stdout and returns the report (also written to
// settings.report_path when set). Throws on bad input or a failed precompute,
// and before any work when an output cannot be written (check_outputs).
// `outputs`, when given, receives the last pose and the deformer state.
nlohmann::json run_scenario(const qpreduce::deform::Scenario& scenario, const qpreduce::deform::TriangleMesh* surface,
                            const qpreduce::deform::TetMesh* solid, const RunSettings& settings,
                            RunOutputs* outputs = nullptr);

// Peak resident set size of this process so far, in MB (getrusage).
double peak_rss_mb();

}  // namespace qpr
