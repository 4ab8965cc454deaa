// `qpr deform MESH …`: reduced ARAP deformation of a mesh from files.
#include "commands.h"
#include "deform_run.h"
#include "guard.h"

#include <qpreduce/deform/mesh_io.h>
#include <qpreduce/deform/tet_io.h>

#include <CLI/CLI.hpp>
#include <fmt/format.h>

#include <memory>
#include <optional>

namespace qpr {

namespace {

using namespace qpreduce;
using namespace qpreduce::deform;

struct DeformArgs {
  std::string mesh, sel, def, anim, scene;
  long linear_proxies = 0, rotational_proxies = 0;
  std::string linear_groups, rotational_clusters, affine_patches;
  int iterations = 8, frames = 1;
  std::optional<double> alpha, beta, soft;
  std::string out, report;
};

bool is_tet_path(const std::string& path) {
  for (const char* ext : {".mesh", ".node", ".ele"})
    if (path.size() >= std::string(ext).size() && path.compare(path.size() - std::string(ext).size(), std::string::npos, ext) == 0)
      return true;
  return false;
}

int run_deform(const DeformArgs& a) {
  const int sources = !a.sel.empty() + !a.anim.empty() + !a.scene.empty();
  if (sources != 1) throw std::invalid_argument("give exactly one of --sel/--def, --anim, --scene");
  if (!a.sel.empty() && a.def.empty()) throw std::invalid_argument("--sel needs --def");

  TriangleMesh surface;
  TetMesh solid;
  bool tet = false;
  Scenario sc;
  if (!a.scene.empty()) {
    const Scene scene = read_scene(a.scene);
    tet = scene.is_tet;
    surface = scene.surface;
    solid = scene.solid;
    sc = scenario_from_scene(scene);
  } else {
    if (a.mesh.empty()) throw std::invalid_argument("MESH is required with --sel/--def and --anim");
    tet = is_tet_path(a.mesh);
    if (tet) solid = read_tet_mesh(a.mesh); else surface = read_triangle_mesh(a.mesh);
    const Vertices& V = tet ? solid.V : surface.V;
    if (!a.sel.empty()) {
      Selection sel = read_sel(a.sel);
      if (tet && sel.size() < V.rows()) {
        // Botsch–Sorkine selections of the surface apply to a tet mesh whose
        // first nodes are that surface (tetgen -Y); interior nodes are free.
        std::fprintf(stderr, "  note: %s has %ld entries for %ld nodes; the remaining nodes are free\n",
                     a.sel.c_str(), static_cast<long>(sel.size()), static_cast<long>(V.rows()));
        sel.roles.resize(static_cast<size_t>(V.rows()), SelRole::Free);
      }
      sc = scenario_from_sel_def(V, sel, read_def(a.def), a.frames);
    } else {
      sc = scenario_from_anim(V, read_anim(a.anim));
    }
    if (tet) sc.model.T = solid.T; else sc.model.F = surface.F;
  }
  const Index n = sc.model.V.rows();
  if (!a.linear_groups.empty()) {
    const VertexIds ids = read_id(a.linear_groups);
    ids.validate(n);
    sc.model.linear = linear_proxies_from_ids(ids.ids, n);
  }
  if (!a.rotational_clusters.empty()) {
    const VertexIds ids = read_id(a.rotational_clusters);
    ids.validate(n);
    const VertexGroups g = rotational_clusters(ids);
    if (tet) {
      sc.model.clusters.resize(static_cast<size_t>(sc.model.T.rows()));
      for (Index t = 0; t < sc.model.T.rows(); ++t) sc.model.clusters[t] = g.group_of[sc.model.T(t, 0)];
    } else {
      sc.model.clusters = g.group_of;
    }
  }
  if (!a.affine_patches.empty()) {
    const VertexIds ids = read_id(a.affine_patches);
    ids.validate(n);
    const VertexGroups g = affine_patches(ids);
    if (sc.model.patch_of_vertex.empty()) sc.model.patch_of_vertex.assign(static_cast<size_t>(n), -1);
    for (const auto& members : g.members) {
      const int id = static_cast<int>(sc.model.patch_types.size());
      for (int v : members) {
        if (sc.model.patch_of_vertex[v] >= 0) {
          throw std::invalid_argument(fmt::format("{}: vertex {} is already in patch {} (from the handles)",
                                                  a.affine_patches, v, sc.model.patch_of_vertex[v]));
        }
        sc.model.patch_of_vertex[v] = id;
      }
      sc.model.patch_types.push_back(PatchType::Affine);
    }
  }
  if (a.soft) {
    sc.constraints.soft = true;
    sc.constraints.delta = *a.soft;
  }

  RunSettings settings;
  settings.name = !a.scene.empty() ? a.scene : a.mesh;
  if (a.linear_proxies > 0) settings.options.linear_proxies = a.linear_proxies;
  if (a.rotational_proxies > 0) settings.options.rotational_proxies = a.rotational_proxies;
  settings.options.iterations = a.iterations;
  if (a.alpha) settings.options.energy.alpha = *a.alpha;
  if (a.beta) settings.options.energy.beta = *a.beta;
  if (tet) settings.options.energy.beta = 0.0;
  settings.out_path = a.out;
  settings.report_path = a.report;
  run_scenario(sc, tet ? nullptr : &surface, tet ? &solid : nullptr, settings);
  return 0;
}

}  // namespace

void register_deform(CLI::App& app) {
  auto a = std::make_shared<DeformArgs>();
  CLI::App* cmd = app.add_subcommand("deform", "Reduced ARAP deformation of a triangle or tet mesh");
  cmd->add_option("mesh", a->mesh, "Mesh: .obj .off .ply (surface) or .mesh .node/.ele (tets)");
  auto* sel = cmd->add_option("--sel", a->sel, "Botsch–Sorkine selection (0 fixed, 1 free, 2 handle)")->check(CLI::ExistingFile);
  cmd->add_option("--def", a->def, "Botsch–Sorkine 4×4 handle transform")->check(CLI::ExistingFile)->needs(sel);
  cmd->add_option("--anim", a->anim, "Recorded handle poses (.anim)")->check(CLI::ExistingFile);
  cmd->add_option("--scene", a->scene, "JSON scene (mesh, handles, patches, proxies, parameters)")->check(CLI::ExistingFile);
  cmd->add_option("--frames", a->frames, "With --sel/--def: frames from rest to the .def pose")->check(CLI::Range(1, 100000));
  auto* lp = cmd->add_option("--linear-proxies", a->linear_proxies, "Linear proxies (farthest-point samples), default 33")
                 ->check(CLI::Range(1L, 10000000L));
  cmd->add_option("--linear-groups", a->linear_groups, "Linear proxies as vertex groups (.id)")->check(CLI::ExistingFile)->excludes(lp);
  auto* rp = cmd->add_option("--rotational-proxies", a->rotational_proxies, "Rotational clusters (spectral k-means), default 27")
                 ->check(CLI::Range(1L, 10000000L));
  cmd->add_option("--rotational-clusters", a->rotational_clusters, "Rotational clusters (.id)")->check(CLI::ExistingFile)->excludes(rp);
  cmd->add_option("--affine-patches", a->affine_patches, "Affine patches (.id: 0 free, k > 0 patch k)")->check(CLI::ExistingFile);
  cmd->add_option("--iterations", a->iterations, "Phase 1/Phase 2 rounds per frame")->check(CLI::Range(1, 1000));
  cmd->add_option("--alpha", a->alpha, "Penalty α on the linearised rotations (Eq. 10)")->check(CLI::NonNegativeNumber);
  cmd->add_option("--beta", a->beta, "Normal penalty β (surfaces, Eq. 10)")->check(CLI::NonNegativeNumber);
  cmd->add_option("--soft", a->soft, "Soft handle constraints with weight δ (Eq. 18) instead of hard ones")->check(CLI::PositiveNumber);
  cmd->add_option("--out", a->out, "Deformed mesh of the last frame ({frame} in the name writes every frame)");
  cmd->add_option("--report", a->report, "JSON report");
  cmd->callback([a]() { run_guarded("deform", [&] { return run_deform(*a); }); });
}

}  // namespace qpr
