// qpreduce::deform — a deformation scenario: a model, its handles and the
// targets of every frame, built from the inputs users bring (Botsch–Sorkine
// .sel/.def, the paper demo's .anim, our JSON scene, or code), plus the
// measurements every report needs (handle residual, ARAP energy).
#pragma once

#include "qpreduce/deform/deformer/deformer.h"
#include "qpreduce/deform/io/handles_io.h"
#include "qpreduce/deform/io/scene.h"
#include "qpreduce/deform/mesh/mesh_check.h"  // kMaxCoordinate, kMaxReach

#include <optional>
#include <string>
#include <vector>

namespace qpreduce::deform {

struct Scenario {
  DeformableMesh model;
  Handles handles;
  std::vector<HandleTargets> frames;  // at least one
  ConstraintOptions constraints;      // hard by default
  // Overrides from a scene file (unset: keep the caller's options).
  std::optional<double> alpha, beta, gamma, psi;
  std::optional<ModelKind> model_kind;
  std::optional<int> iterations;
  // Proxy counts a scene gives as numbers (not as .id files).
  std::optional<Index> linear_proxies, rotational_proxies;
};

// Checks what would otherwise surface deep in the solve as "contains NaN" or
// "not strictly convex … condition inf": every mesh coordinate within
// kMaxCoordinate in magnitude, every frame's handle targets within kMaxReach
// bounding-box diagonals of the rest pose's centre (reach_in_frame, as
// Deformer::frame judges them), and every connected component of the
// elements anchored by a point handle, a fixed patch or a prescribed patch.
// Throws std::invalid_argument "<source>: …" naming the vertex, frame or
// component. (kMaxCoordinate and kMaxReach are in mesh_check.h, whose
// diagnose_mesh checks all of the mesh's side of this and more.)
void check_scenario(const Scenario& scenario, const std::string& source);

// Handles that cannot hold in one frame: a vertex pinned by two single-vertex
// point handles to places more than 1e-9 bounding-box diagonals apart, or
// pinned inside a fixed patch away from its rest position (the solve would
// split the difference). Throws std::invalid_argument "<source>: vertex v is
// held at two places by point handles i and j ([frame f: ]d bounding-box
// diagonals apart)"; `frame` < 0 is not named. Targets beyond the handles'
// count are not read.
void check_handle_targets(const DeformableMesh& model, const Handles& handles, const HandleTargets& targets,
                          Index frame, const std::string& source);

// One flag per vertex (n entries), non-zero for a vertex the handles hold: in
// a point handle, a fixed patch or a prescribed patch (diagnose_mesh's anchors).
// Throws std::invalid_argument when the handles or the patch labels do not
// fit the model (a vertex or patch out of range).
std::vector<char> anchored_vertices(const Scenario& scenario);

// Applies the scenario's overrides (α, β, γ, model, ψ, iterations, proxy
// counts) to `options`.
void apply_scenario_options(const Scenario& scenario, DeformerOptions* options);

// .sel/.def: a Fixed patch (role 0) and an Affine handle patch (role 2) moved
// by `def`; `frames` frames interpolate from the rest pose to `def` (the
// rotation by its axis–angle, the rest linearly), the last one being `def`.
Scenario scenario_from_sel_def(const Vertices& V, const Selection& sel, const Eigen::Matrix4d& def, int frames = 1);

// .anim: one point handle per animation handle (its weighted vertices), one
// frame per recorded point list.
Scenario scenario_from_anim(const Vertices& V, const HandleAnimation& anim);

// JSON scene: handles (vertex lists pinned point by point, or weighted
// groups), patches, proxies given as .id files, energy parameters.
Scenario scenario_from_scene(const Scene& scene);

// Largest distance between where the handles are in `deformed` and where the
// targets put them: point handles by their weighted point, patch handles by
// every vertex of the patch, Fixed patches by every vertex at rest.
double handle_residual(const Scenario& scenario, const HandleTargets& targets, const Vertices& deformed);

}  // namespace qpreduce::deform
