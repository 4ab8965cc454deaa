// Scenarios from .sel/.def, .anim and JSON scenes (docs/formats.md); see scenario.h.
#include <qpreduce/support.h>
#include "qpreduce/deform/io/scenario.h"

#include <Eigen/Geometry>
#include <fmt/format.h>

#include <algorithm>

namespace qpreduce::deform {

namespace {

void add_patch(DeformableMesh* model, PatchType type, const std::vector<int>& vertices, const std::string& what) {
  const Index n = model->V.rows();
  if (model->patch_of_vertex.empty()) model->patch_of_vertex.assign(static_cast<size_t>(n), -1);
  const int id = static_cast<int>(model->patch_types.size());
  for (int v : vertices) {
    if (v < 0 || v >= n) throw std::invalid_argument(fmt::format("{}: vertex {} outside [0, {})", what, v, n));
    if (model->patch_of_vertex[v] >= 0) {
      throw std::invalid_argument(
          fmt::format("{}: vertex {} is already in patch {}", what, v, model->patch_of_vertex[v]));
    }
    model->patch_of_vertex[v] = id;
  }
  model->patch_types.push_back(type);
}

Eigen::Matrix<double, 3, 4> interpolate_affine(const Eigen::Matrix4d& M, double a) {
  // Rotation part by axis–angle of its nearest rotation, the remaining
  // stretch and the translation linearly.
  const Eigen::Matrix3d A = M.topLeftCorner<3, 3>();
  const Eigen::Matrix3d R = fit_rotation(A);
  const Eigen::AngleAxisd aa(R);
  const Eigen::Matrix3d Ra = Eigen::AngleAxisd(a * aa.angle(), aa.axis()).toRotationMatrix();
  const Eigen::Matrix3d stretch = R.transpose() * A;  // A = R·stretch
  Eigen::Matrix<double, 3, 4> T;
  T.leftCols<3>() = Ra * ((1 - a) * Eigen::Matrix3d::Identity() + a * stretch);
  T.col(3) = a * M.block<3, 1>(0, 3);
  return T;
}


// The mesh, patches and proxies of a scene.
DeformableMesh model_from_scene(const Scene& scene) {
  DeformableMesh model;
  model.V = scene.rest_positions();
  if (scene.is_tet) {
    model.T = scene.solid.T;
  } else {
    model.F = scene.surface.F;
  }
  const Index n = model.V.rows();
  for (size_t p = 0; p < scene.patches.size(); ++p)
    add_patch(&model, scene.patches[p].type, scene.patches[p].vertices, fmt::format("scene patch {}", p));
  for (const auto& members : scene.affine_patches.groups.members)
    add_patch(&model, PatchType::Affine, members, "affine patch file");
  if (!scene.linear_proxies.groups.members.empty()) {
    std::vector<std::vector<Index>> groups;
    for (const auto& g : scene.linear_proxies.groups.members) groups.emplace_back(g.begin(), g.end());
    model.linear = linear_proxies_from_groups(groups, n);
  }
  if (!scene.rotational_clusters.groups.group_of.empty()) {
    const std::vector<int>& per_vertex = scene.rotational_clusters.groups.group_of;
    model.clusters = scene.is_tet ? element_clusters_from_vertex_labels(per_vertex, model.T) : per_vertex;
  }
  return model;
}

// The scene's energy and solver settings as the scenario's overrides.
void apply_scene_settings(const Scene& scene, Scenario* sc) {
  sc->alpha = scene.alpha;
  sc->beta = scene.beta;
  sc->gamma = scene.gamma;
  sc->psi = scene.psi;
  if (scene.model) sc->model_kind = *scene.model == "conformal" ? ModelKind::Conformal : ModelKind::Arap;
  sc->iterations = scene.iterations;
  if (scene.constraints == ConstraintMode::Soft) {
    sc->constraints.soft = true;
    if (scene.delta) sc->constraints.delta = *scene.delta;
  }
}

// Per scene handle, the model patch it prescribes, or -1: a vertex-list
// handle moved by transforms whose vertices are exactly a Rigid or Affine
// scene patch prescribes that patch's transform (12 rows, not 3 per vertex).
std::vector<Index> patches_of_handles(const Scene& scene, const DeformableMesh& model) {
  std::vector<Index> patch_of_handle(scene.handles.size(), -1);
  for (size_t k = 0; k < scene.handles.size(); ++k) {
    const SceneHandle& h = scene.handles[k];
    if (h.is_group() || h.transforms.empty()) continue;
    std::vector<int> vs = h.vertices;
    std::sort(vs.begin(), vs.end());
    for (size_t p = 0; p < scene.patches.size(); ++p)
      if (scene.patches[p].type != PatchType::Fixed && scene.patches[p].vertices == vs)
        patch_of_handle[k] = model.patch_of_vertex[static_cast<size_t>(vs.front())];
  }
  return patch_of_handle;
}

// Handles: a patch handle prescribes its patch, a group is one weighted
// point, and any other vertex list pins each vertex.
Handles handles_from_scene(const Scene& scene, const std::vector<Index>& patch_of_handle) {
  Handles handles;
  for (size_t k = 0; k < scene.handles.size(); ++k) {
    const SceneHandle& h = scene.handles[k];
    if (patch_of_handle[k] >= 0) {
      handles.patches.push_back(patch_of_handle[k]);
    } else if (h.is_group()) {
      PointHandle ph;
      ph.vertices.assign(h.vertices.begin(), h.vertices.end());
      ph.weights = h.weights;
      handles.points.push_back(ph);
    } else {
      for (int v : h.vertices) handles.points.push_back({{v}, {}});
    }
  }
  return handles;
}

// The targets of frame f, in the order of handles_from_scene (a handle with
// fewer frames holds its last one).
HandleTargets scene_targets(const Scene& scene, const std::vector<Index>& patch_of_handle, const Scenario& sc,
                            Index f) {
  HandleTargets t;
  t.points.resize(static_cast<Index>(sc.handles.points.size()), 3);
  Index row = 0;
  for (size_t k = 0; k < scene.handles.size(); ++k) {
    const SceneHandle& h = scene.handles[k];
    if (patch_of_handle[k] >= 0) {
      const size_t i = static_cast<size_t>(std::min<Index>(f, static_cast<Index>(h.transforms.size()) - 1));
      t.patch_transforms.push_back(h.transforms[i].topRows<3>());
      continue;
    }
    const Vertices pts = h.targets_at(f, sc.model.V);
    t.points.middleRows(row, pts.rows()) = pts;
    row += pts.rows();
  }
  return t;
}

}  // namespace

Scenario scenario_from_sel_def(const Vertices& V, const Selection& sel, const Eigen::Matrix4d& def, int frames) {
  sel.validate(V.rows());
  if (frames < 1) throw std::invalid_argument(fmt::format("scenario_from_sel_def: frames must be ≥ 1, got {}", frames));
  Scenario sc;
  sc.model.V = V;
  std::vector<int> roles(sel.roles.size());
  for (size_t i = 0; i < roles.size(); ++i) roles[i] = static_cast<int>(sel.roles[i]);
  const SelDefScenario sd = apply_sel_def(roles, def, &sc.model);
  sc.handles = sd.handles;
  for (int f = 1; f <= frames; ++f) {
    HandleTargets t;
    t.points.resize(0, 3);
    t.patch_transforms = {f == frames ? Eigen::Matrix<double, 3, 4>(def.topRows<3>())
                                      : interpolate_affine(def, static_cast<double>(f) / frames)};
    sc.frames.push_back(t);
  }
  return sc;
}

Scenario scenario_from_anim(const Vertices& V, const HandleAnimation& anim) {
  anim.validate(V.rows());
  Scenario sc;
  sc.model.V = V;
  const SparseMatrix<double> Wt = anim.weights.transpose();  // n × handles, columns = handles
  for (Index h = 0; h < anim.handles(); ++h) {
    PointHandle ph;
    for (SparseMatrix<double>::InnerIterator it(Wt, h); it; ++it) {
      ph.vertices.push_back(it.row());
      ph.weights.push_back(it.value());
    }
    if (ph.vertices.empty()) throw std::invalid_argument(fmt::format("{}: handle {} has no vertex", anim.source, h));
    if (ph.vertices.size() == 1 && ph.weights[0] == 1.0) ph.weights.clear();
    sc.handles.points.push_back(ph);
  }
  for (const Vertices& pts : anim.targets) {
    HandleTargets t;
    t.points = pts;
    sc.frames.push_back(t);
  }
  if (sc.frames.empty()) throw std::invalid_argument(anim.source + ": no recorded pose");
  return sc;
}

Scenario scenario_from_scene(const Scene& scene) {
  Scenario sc;
  sc.model = model_from_scene(scene);
  apply_scene_settings(scene, &sc);
  const std::vector<Index> patch_of_handle = patches_of_handles(scene, sc.model);
  sc.handles = handles_from_scene(scene, patch_of_handle);
  const Index frames = std::max<Index>(1, scene.frames);
  for (Index f = 0; f < frames; ++f) sc.frames.push_back(scene_targets(scene, patch_of_handle, sc, f));
  return sc;
}

double handle_residual(const Scenario& sc, const HandleTargets& targets, const Vertices& deformed) {
  return handle_residual(sc.model, sc.handles, targets, deformed);
}

void apply_scenario_options(const Scenario& sc, DeformerOptions* options) {
  if (sc.alpha) options->energy.alpha = *sc.alpha;
  if (sc.beta) options->energy.beta = *sc.beta;
  if (sc.gamma) options->energy.gamma = *sc.gamma;
  if (sc.model_kind) options->model = *sc.model_kind;
  if (sc.psi) options->conformal_bound = *sc.psi;
  if (sc.iterations) options->iterations = *sc.iterations;
}

}  // namespace qpreduce::deform
