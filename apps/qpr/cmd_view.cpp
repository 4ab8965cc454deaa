// `qpr view MESH …`: the interactive deformation viewer (apps/viewer), or with
// --screenshot a headless render of the scenario's last frame.
#include "commands.h"
#include "deform_run.h"
#include "guard.h"
#include "refine_run.h"
#include "validators.h"

#include <viewer.h>

#include <qpreduce/deform/mesh/tet_boundary.h>

#include <CLI/CLI.hpp>

#include <map>
#include <memory>
#include <utility>

namespace qpr {

namespace {

struct ViewArgs : ScenarioArgs {
  viewer::ViewerOptions view;
  RefineArgs refine;
  std::string size = "1280x800", color = "clusters", reconstruction = "gpu", up = "y";
};

int run_view(ViewArgs& a) {
  for (const auto& [path, what] : {std::pair{&a.view.screenshot, "screenshot"},
                                   {&a.view.out_mesh, "mesh"},
                                   {&a.view.stats_json, "stats"},
                                   {&a.view.window_screenshot, "window screenshot"},
                                   {&a.view.window_log, "window log"}})
    if (!path->empty()) qpreduce::check_destination(*path, what);
  LoadedScenario ls = load_scenario(a);
  viewer::ViewerOptions& o = a.view;
  if (std::sscanf(a.size.c_str(), "%dx%d", &o.width, &o.height) != 2)
    throw std::invalid_argument("--size: expected WIDTHxHEIGHT, got '" + a.size + "'");
  o.color = std::map<std::string, viewer::ColorMode>{{"clusters", viewer::ColorMode::Clusters},
                                                     {"linear", viewer::ColorMode::LinearProxies},
                                                     {"patches", viewer::ColorMode::Patches},
                                                     {"deviation", viewer::ColorMode::Deviation}}.at(a.color);
  o.reconstruction = a.reconstruction == "cpu" ? viewer::Reconstruction::Cpu : viewer::Reconstruction::Gpu;
  o.up_axis = a.up == "x" ? 0 : a.up == "z" ? 2 : 1;
  if (a.refine.tolerance) o.refine = refine_options(a.refine);

  viewer::ViewerInput input;
  input.name = ls.name;
  input.exact_handles = a.exact_handles;
  input.options = ls.options;
  qpreduce::deform::apply_scenario_options(ls.scenario, &input.options);
  input.faces = !ls.tet ? ls.surface.F : ls.solid.F.rows() > 0 ? ls.solid.F : qpreduce::deform::boundary_faces(ls.solid.T);
  input.scenario = std::move(ls.scenario);
  const auto save = [&ls](const std::string& path, const qpreduce::deform::Vertices& V) {
    write_pose(path, V, ls.tet ? nullptr : &ls.surface, ls.tet ? &ls.solid : nullptr);
  };
  return viewer::run_viewer(std::move(input), o, save);
}

}  // namespace

void register_view(CLI::App& app) {
  auto [cmd, a] = add_command<ViewArgs>(app, "view", "Interactive deformation viewer (GLFW + Dear ImGui); --screenshot renders headless");
  add_scenario_options(cmd, a.get());
  add_path_option(cmd, PathRole::Output, "--screenshot", a->view.screenshot, "Headless: run the scenario's frames, write this PNG and exit");
  cmd->add_option("--size", a->size, "Window / image size WIDTHxHEIGHT (default 1280x800)");
  cmd->add_option("--samples", a->view.samples, "MSAA samples (default 4)")->check(whole_number_between(0, 16));
  cmd->add_option("--reconstruction", a->reconstruction, "gpu (default; CPU fallback when it does not fit) or cpu")
      ->check(CLI::IsMember({"gpu", "cpu"}));
  cmd->add_option("--color", a->color, "clusters (default), linear, patches or deviation")
      ->check(CLI::IsMember({"clusters", "linear", "patches", "deviation"}));
  cmd->add_option("--deviation-scale", a->view.deviation_scale,
                  "Deviation shown at the top of the ramp, / bbox diagonal (0.1)")
      ->check(number_above(0));
  cmd->add_option("--up", a->up, "World axis shown upwards: x, y (default) or z")->check(CLI::IsMember({"x", "y", "z"}));
  cmd->add_option("--yaw", a->view.yaw_deg, "Camera yaw about the up axis, degrees (0)")
      ->check(number_between(-360.0, 360.0));
  cmd->add_option("--pitch", a->view.pitch_deg, "Camera elevation, degrees (15)")->check(number_between(-89.0, 89.0));
  cmd->add_option("--zoom", a->view.zoom, "Zoom steps, > 0 closer (0)")->check(number_between(-100.0, 100.0));
  cmd->add_flag("!--no-handles", a->view.show_handles, "Do not draw the handle vertices");
  add_path_option(cmd, PathRole::Output, "--out", a->view.out_mesh, "Headless: also write the last pose (mesh)");
  add_path_option(cmd, PathRole::Output, "--stats", a->view.stats_json, "Headless: JSON with timings, the path used and GPU/CPU agreement");
  // Headless: refine the last frame and report it; interactive: the settings
  // of the refine that starts when the handles are still.
  add_refine_options(cmd, &a->refine);
  add_path_option(cmd, PathRole::Input, "--replay", a->view.replay, "Recorded handle motion (JSON, from the viewer's Record) to play")
      ->check(CLI::ExistingFile);
  cmd->add_option("--max-frames", a->view.max_frames,
                  "Interactive: close after N frames (smoke tests; with --replay, N frames after the precompute)")
      ->check(whole_number_between(0, 1000000000));
  add_path_option(cmd, PathRole::Output, "--window-screenshot", a->view.window_screenshot,
                  "Interactive with --max-frames: save the whole window (panels too) at the last frame");
  add_path_option(cmd, PathRole::Output, "--window-log", a->view.window_log,
                  "Interactive: write a JSON log of every frame (times, refine start / shown / cancel) at exit");
  cmd->callback([a = a]() { run_guarded("view", [&] { return run_view(*a); }); });
}

}  // namespace qpr
