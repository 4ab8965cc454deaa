// `qpr check MESH [--sel F | --anim F | --scene F] [--report F] [--strict]`: the mesh
// pre-flight (diagnose_mesh) on its own: every finding, the scale, and an
// exit code — 0 clean, 1 warnings only, 2 errors (or warnings with --strict,
// or an input that cannot be read).
#include "reports.h"
#include "commands.h"
#include "guard.h"
#include "preflight.h"

#include <qpreduce/util/atomic_file.h>
#include <qpreduce/deform/io/file_kind.h>
#include <qpreduce/deform/io/handles_io.h>
#include <qpreduce/deform/io/mesh_io.h>
#include <qpreduce/deform/io/tet_io.h>

#include <CLI/CLI.hpp>
#include <fmt/format.h>

#include <filesystem>
#include <memory>
#include <stdexcept>

namespace qpr {

namespace {

using namespace qpreduce::deform;

struct CheckArgs {
  std::string mesh, sel, scene, anim, report;
  bool strict = false;
};

// Exit codes (docs/robustness.md).
constexpr int kCheckWarnings = 1, kCheckErrors = 2;

// The mesh and its anchors: from the scene, or from MESH with the fixed and
// handle vertices of --sel or the handles' vertices of --anim (none without
// either: anchoring is then not checked).
struct CheckInputs {
  Vertices V;
  Eigen::Matrix<int, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> E;
  std::vector<char> anchored;
  std::string name, anchors;  // what is checked; where the anchors come from
};

CheckInputs read_inputs(const CheckArgs& a) {
  CheckInputs in;
  if (!a.scene.empty()) {
    const Scene scene = read_scene(a.scene);
    if (!a.mesh.empty() && !std::filesystem::equivalent(a.mesh, scene.mesh_path))
      throw std::invalid_argument(fmt::format("{} names the mesh {}, not {}", a.scene, scene.mesh_path, a.mesh));
    const Scenario sc = scenario_from_scene(scene);
    in.V = sc.model.V;
    if (sc.model.is_tet()) in.E = sc.model.T; else in.E = sc.model.F;
    in.anchored = anchored_vertices(sc);
    in.name = scene.mesh_path;
    in.anchors = a.scene;
    return in;
  }
  if (a.mesh.empty()) throw std::invalid_argument("give MESH, or --scene");
  in.name = a.mesh;
  if (mesh_file_kind(a.mesh) == MeshFileKind::Tets) {
    TetMesh t = read_tet_mesh(a.mesh);
    in.V = std::move(t.V);
    in.E = t.T;
  } else {
    TriangleMesh s = read_triangle_mesh(a.mesh);
    in.V = std::move(s.V);
    in.E = s.F;
  }
  if (!a.sel.empty()) {
    const Selection sel = read_sel(a.sel);
    // A surface selection of a tet mesh covers its first nodes (tetgen -Y), as in `qpr deform`.
    if (sel.size() > in.V.rows() || (in.E.cols() == 3 && sel.size() != in.V.rows())) sel.validate(in.V.rows());
    in.anchored.assign(static_cast<size_t>(in.V.rows()), 0);
    for (size_t v = 0; v < sel.roles.size(); ++v) in.anchored[v] = sel.roles[v] != SelRole::Free;
    in.anchors = a.sel;
  }
  if (!a.anim.empty()) {
    if (in.E.cols() != 3) throw std::invalid_argument("--anim: recorded handle poses are for triangle meshes");
    in.anchored = anchored_vertices(scenario_from_anim(in.V, read_anim(a.anim)));
    in.anchors = a.anim;
  }
  return in;
}

// The console summary: sizes, scale, findings, status.
void print_summary(const CheckInputs& in, const MeshCheckSummary& s, bool strict) {
  const char* element = s.corners == 4 ? "tet" : "triangle";
  fmt::print("{}: {} vertices, {} {}s, {} connected component{}\n", in.name, s.vertices, s.elements, element,
             s.components, s.components == 1 ? "" : "s");
  fmt::print("  anchors: {}\n", in.anchors.empty() ? "not checked (no --sel, --anim or --scene)" : "from " + in.anchors);
  if (s.diagonal > 0.0) {
    fmt::print("  scale: bounding box ({:.4g}, {:.4g}, {:.4g}) to ({:.4g}, {:.4g}, {:.4g}), diagonal {:.4g}\n",
               s.box_min(0), s.box_min(1), s.box_min(2), s.box_max(0), s.box_max(1), s.box_max(2), s.diagonal);
    fmt::print("  edges: {:.3g} to {:.3g}; worst {} quality {:.3g} (1 for a regular {})\n", s.shortest_edge,
               s.longest_edge, element, s.worst_quality, element);
  }
  print_findings(stdout, s, strict, "  ");
  const std::string status = check_status(s, strict);
  fmt::print("  status: {}{}   ({:.1f} ms)\n", status,
             strict && s.has_warnings() && !s.has_errors() ? " (--strict: warnings are errors)" : "",
             1e3 * s.seconds);
}

int run_check(const CheckArgs& a) {
  if (!a.sel.empty() + !a.scene.empty() + !a.anim.empty() > 1)
    throw std::invalid_argument("give one of --sel, --anim and --scene, not several");
  if (!a.report.empty()) qpreduce::check_destination(a.report, "report");
  const CheckInputs in = read_inputs(a);
  const MeshCheckSummary s = diagnose_mesh(in.V, in.E, in.anchored);
  print_summary(in, s, a.strict);
  if (!a.report.empty()) {
    nlohmann::json report = check_json(s, a.strict);
    report["mesh"] = in.name;
    report["anchors"] = in.anchors;
    write_json(run_files().stage(a.report), report);
  }
  const std::string status = check_status(s, a.strict);
  return status == "errors" ? kCheckErrors : status == "warnings" ? kCheckWarnings : 0;
}

}  // namespace

void register_check(CLI::App& app) {
  auto [cmd, a] = add_command<CheckArgs>(
      app, "check",
      "Pre-flight diagnostics of a mesh: degenerate elements, duplicate and unreferenced vertices, non-manifold "
      "parts, inverted tets, unanchored components, scale (exit 0 clean, 1 warnings, 2 errors)");
  add_path_option(cmd, PathRole::Input, "mesh", a->mesh, "Mesh: .obj .off .ply (surface) or .mesh .node/.ele (tets)");
  add_path_option(cmd, PathRole::Input, "--sel", a->sel, "Botsch–Sorkine selection: its fixed and handle vertices anchor the components")
      ->check(CLI::ExistingFile);
  add_path_option(cmd, PathRole::Input, "--anim", a->anim, "Recorded handle poses (.anim): the handles' vertices anchor the components")
      ->check(CLI::ExistingFile);
  add_path_option(cmd, PathRole::Scene, "--scene", a->scene, "JSON scene: its mesh, and its handles and fixed patches as anchors")
      ->check(CLI::ExistingFile);
  add_path_option(cmd, PathRole::Output, "--report", a->report, "JSON report");
  cmd->add_flag("--strict", a->strict, "Warnings are errors (exit 2)");
  cmd->callback([a = a]() { run_guarded("check", [&] { return run_check(*a); }, {1, 2}, /*linear_algebra=*/false); });
}

}  // namespace qpr
