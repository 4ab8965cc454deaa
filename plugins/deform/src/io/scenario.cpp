// Scenarios from .sel/.def, .anim and JSON scenes (docs/formats.md); see scenario.h.
#include "qpreduce/deform/io/scenario.h"
#include "qpreduce/deform/mesh/geometry.h"

#include "deformer/handle_checks.h"

#include <Eigen/Geometry>
#include <fmt/format.h>

#include <algorithm>
#include <map>
#include <string>

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
  if (scene.linear_proxies.count > 0 && scene.linear_proxies.id_file.empty())
    sc->linear_proxies = scene.linear_proxies.count;
  if (scene.rotational_clusters.count > 0 && scene.rotational_clusters.id_file.empty())
    sc->rotational_proxies = scene.rotational_clusters.count;
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

// Two targets closer than this (relative to the bounding-box diagonal) are one
// place: round-off of the same transform applied twice, not a conflict.
constexpr double kSamePlace = 1e-9;

// check_handle_targets on every frame of the scenario.
void check_conflicting_pins(const Scenario& sc, const std::string& source) {
  for (size_t f = 0; f < sc.frames.size(); ++f)
    check_handle_targets(sc.model, sc.handles, sc.frames[f], static_cast<Index>(f), source);
}

}  // namespace

void check_handle_targets(const DeformableMesh& model, const Handles& handles, const HandleTargets& targets,
                          Index frame, const std::string& source) {
  const Vertices& V = model.V;
  const double diag = V.rows() > 0 ? (V.colwise().maxCoeff() - V.colwise().minCoeff()).norm() : 0.0;
  const double tol = kSamePlace * diag;
  const std::string at = frame >= 0 ? fmt::format("frame {}: ", frame) : std::string();
  std::map<Index, Index> first_pin;  // vertex → its first single-vertex point handle
  const Index h = std::min<Index>(static_cast<Index>(handles.points.size()), targets.points.rows());
  for (Index k = 0; k < h; ++k) {
    const PointHandle& ph = handles.points[static_cast<size_t>(k)];
    if (ph.vertices.size() != 1 || !ph.weights.empty()) continue;
    const Index v = ph.vertices[0];
    if (v < 0 || v >= V.rows()) continue;  // refused by the handle checks, with their words
    const auto [it, fresh] = first_pin.emplace(v, k);
    const int patch = static_cast<size_t>(v) < model.patch_of_vertex.size() ? model.patch_of_vertex[v] : -1;
    const bool in_fixed = patch >= 0 && static_cast<size_t>(patch) < model.patch_types.size() &&
                          model.patch_types[static_cast<size_t>(patch)] == PatchType::Fixed;
    const Eigen::RowVector3d target = targets.points.row(k);
    const double to_other = fresh ? 0.0 : (target - targets.points.row(it->second)).norm();
    const double to_rest = in_fixed ? (target - V.row(v)).norm() : 0.0;
    if (to_other > tol)
      throw std::invalid_argument(fmt::format(
          "{}: vertex {} is held at two places by point handles {} and {} ({}{:.3g} bounding-box diagonals apart)",
          source, v, it->second, k, at, to_other / std::max(diag, 1e-300)));
    if (to_rest > tol)
      throw std::invalid_argument(fmt::format(
          "{}: vertex {} is in fixed patch {} but point handle {} moves it ({}{:.3g} bounding-box diagonals from "
          "rest)",
          source, v, patch, k, at, to_rest / std::max(diag, 1e-300)));
  }
}

std::vector<char> anchored_vertices(const Scenario& sc) {
  // A Scenario from Python may have had its model or handles replaced.
  detail::check_patch_labels(sc.model, "anchored_vertices");
  detail::check_handles(sc.handles, sc.model.V.rows(), sc.model.patch_types);
  std::vector<char> anchored(static_cast<size_t>(sc.model.V.rows()), 0);
  for (const PointHandle& h : sc.handles.points)
    for (Index v : h.vertices) anchored[static_cast<size_t>(v)] = 1;
  for (size_t v = 0; v < sc.model.patch_of_vertex.size(); ++v) {
    const int p = sc.model.patch_of_vertex[v];
    if (p < 0) continue;
    const bool prescribed = std::find(sc.handles.patches.begin(), sc.handles.patches.end(), p) !=
                            sc.handles.patches.end();
    if (prescribed || sc.model.patch_types[static_cast<size_t>(p)] == PatchType::Fixed) anchored[v] = 1;
  }
  return anchored;
}

void check_scenario(const Scenario& sc, const std::string& source) {
  const Vertices& V = sc.model.V;
  for (Index v = 0; v < V.rows(); ++v)
    if (!(V.row(v).cwiseAbs().maxCoeff() <= kMaxCoordinate))
      throw std::invalid_argument(fmt::format("{}: vertex {} at ({:g}, {:g}, {:g}): coordinates beyond {:g} overflow "
                                              "in the energy",
                                              source, v, V(v, 0), V(v, 1), V(v, 2), kMaxCoordinate));
  // Targets as Deformer::frame judges them: in the rest pose's frame.
  const Normalization frame = normalization_of(V);
  for (size_t f = 0; f < sc.frames.size(); ++f) {
    std::string where;
    const double reach = reach_in_frame(sc.frames[f], frame, sc.handles, &where);
    if (!(reach <= kMaxReach))
      throw std::invalid_argument(fmt::format("{}: frame {}: {}", source, f, reach_message(where, reach)));
  }
  const MeshComponents components = sc.model.is_tet() ? connected_components(V.rows(), sc.model.T)
                                                       : connected_components(V.rows(), sc.model.F);
  const MeshFinding loose = unanchored_components(components, anchored_vertices(sc), 1);
  if (loose.count > 0) throw std::invalid_argument(fmt::format("{}: {}", source, loose.message));
}

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
  check_conflicting_pins(sc, scene.source);
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
  if (sc.linear_proxies) options->linear_proxies = *sc.linear_proxies;
  if (sc.rotational_proxies) options->rotational_proxies = *sc.rotational_proxies;
}

}  // namespace qpreduce::deform
