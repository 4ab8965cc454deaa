// qpreduce::deform — our JSON scene: a mesh, its handles and patches, the
// proxies and the energy/solver parameters, in one file.
//
// The schema, with an example, is in docs/formats.md ("JSON scene").
// read_scene() parses the file (nlohmann-json), resolves every path relative
// to the scene file's directory, loads the mesh and every referenced
// .sel/.def/.id/.anim file, and checks everything against the mesh: vertex
// indices in range, per-file vertex counts, one frame count for all handles.
// Any problem throws IoError naming the scene file and the JSON pointer of
// the offending value ("scene.json: /handles/1/targets/0: expected 3 numbers,
// got 2"), or the referenced file.
#pragma once

#include <qpreduce/deform/deformer/handles.h>
#include <qpreduce/deform/io/handles_io.h>
#include <qpreduce/deform/io/io_error.h>
#include <qpreduce/deform/mesh/mesh.h>

#include <Eigen/Core>

#include <optional>
#include <string>
#include <vector>

namespace qpreduce::deform {

struct ScenePatch {
  PatchType type = PatchType::Fixed;
  std::vector<int> vertices;  // ascending, no duplicates
};

// A handle is either a list of vertices, each pinned on its own (weights
// empty), or a weighted group: the single point Σ_i weights[i]·v_{vertices[i]}.
// Its motion is given per frame by target points or by 4 × 4 affine
// transforms of the rest positions (exactly one of the two is non-empty). A
// handle with one frame keeps that pose in every frame of the scene.
struct SceneHandle {
  std::string name;
  std::vector<int> vertices;
  std::vector<double> weights;
  // Per frame, points() × 3.
  std::vector<Vertices> targets;
  // Per frame, applied to column vectors: p ↦ M[0:3,0:3]·p + M[0:3,3].
  std::vector<Eigen::Matrix4d> transforms;

  bool is_group() const { return !weights.empty(); }
  // Number of constrained points: 1 for a group, vertices.size() otherwise.
  Index points() const;
  Index frames() const;
  // The points() × 3 target positions at `frame` (frame ≥ frames() reuses
  // the last frame, so a one-frame handle is static). `rest` is the mesh's
  // rest positions, used by transform handles.
  Vertices targets_at(Index frame, const Vertices& rest) const;
};

// Proxies given by a count (to be computed by the plugin) or by an .id file.
struct ProxySpec {
  Index count = 0;      // 0: not given, the plugin's default applies
  std::string id_file;  // resolved path, when given as a file
  VertexGroups groups;  // from id_file; then count == groups.size()
};

enum class ConstraintMode { Hard, Soft };

// One file a scene names: where it is named (a JSON pointer: "/mesh",
// "/handles/0/sel/file") and its path, resolved against the scene's folder.
struct SceneFile {
  std::string where;
  std::string path;
};

struct Scene {
  std::string source;     // the scene file
  std::string mesh_path;  // resolved path of the mesh
  bool is_tet = false;    // .mesh/.node/.ele meshes are tet meshes
  TriangleMesh surface;   // filled when !is_tet
  TetMesh solid;          // filled when is_tet

  // Energy weights of the modified energy E′ (Eq. 8–11); unset: plugin default.
  std::optional<double> alpha, beta, gamma;
  // Deformation model, "arap" or "conformal", and the conformal bound ψ > 1
  // (/energy/model, /energy/psi); unset: plugin default.
  std::optional<std::string> model;
  std::optional<double> psi;
  // Alternation iterations per frame; unset: plugin default.
  std::optional<int> iterations;
  ConstraintMode constraints = ConstraintMode::Hard;
  // Soft-constraint parameter δ (> 0); unset: plugin default.
  std::optional<double> delta;

  ProxySpec linear_proxies, rotational_clusters, affine_patches;
  std::vector<ScenePatch> patches;
  std::vector<SceneHandle> handles;
  // The largest frames() over the handles (0 without handles).
  Index frames = 0;
  // Every file the scene names, in the order read (a file named twice is
  // listed twice; a TetGen mesh by the path given, not its siblings).
  std::vector<SceneFile> files;

  const Vertices& rest_positions() const { return is_tet ? solid.V : surface.V; }
  Index vertex_count() const { return rest_positions().rows(); }
};

Scene read_scene(const std::string& path);

// The files read_scene(path) would read, found in the JSON alone: nothing
// else is opened or checked. For the check that no output of a command is
// one of its inputs before any work. Throws IoError, as read_scene does, when
// the scene file cannot be read or is not JSON.
std::vector<SceneFile> scene_files(const std::string& path);

}  // namespace qpreduce::deform
