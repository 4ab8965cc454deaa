// `qpr deform MESH …`: reduced ARAP deformation of a mesh from files.
#include "commands.h"
#include "deform_run.h"
#include "guard.h"
#include "refine_run.h"

#include <CLI/CLI.hpp>

#include <memory>
#include <string>

namespace qpr {

namespace {

struct DeformArgs : ScenarioArgs {
  std::string out, report, cache;
  RefineArgs refine;
  bool strict = false;
};

int run_deform(const DeformArgs& a) {
  LoadedScenario ls = load_scenario(a, a.strict);
  RunSettings settings;
  settings.name = ls.name;
  settings.run.deformer = ls.options;
  settings.out_path = a.out;
  if (a.out.find("{frame}") != std::string::npos) {  // every frame, as --out's help says
    settings.write_frames.clear();
    for (int f = 0; f < static_cast<int>(ls.scenario.frames.size()); ++f) settings.write_frames.push_back(f);
  }
  settings.report_path = a.report;
  settings.run.cache_path = a.cache;
  if (a.refine.tolerance) settings.run.refine = refine_options(a.refine);
  settings.run.strict = a.strict;
  settings.preflight = ls.preflight;
  run_scenario(ls.scenario, ls.tet ? nullptr : &ls.surface, ls.tet ? &ls.solid : nullptr, settings);
  return 0;
}

}  // namespace

void register_deform(CLI::App& app) {
  auto [cmd, a] = add_command<DeformArgs>(app, "deform", "Reduced ARAP deformation of a triangle or tet mesh");
  add_scenario_options(cmd, a.get());
  add_path_option(cmd, PathRole::Output, "--out", a->out, "Deformed mesh of the last frame ({frame} in the name writes every frame)");
  add_path_option(cmd, PathRole::Output, "--report", a->report, "JSON report");
  add_path_option(cmd, PathRole::Cache, "--cache", a->cache,
                  "Precomputed model: loaded when it exists and matches the inputs, else precomputed and written");
  add_refine_options(cmd, &a->refine);
  cmd->add_flag("--strict", a->strict,
                "Warnings are errors: handles that hold only in the least-squares sense, and the mesh pre-flight's "
                "warnings (near-degenerate elements, duplicate or unreferenced vertices, …; see qpr check)");
  cmd->callback([a = a]() { run_guarded("deform", [&] { return run_deform(*a); }); });
}

}  // namespace qpr
