// qpreduce::deform — handle and proxy inputs: Botsch–Sorkine `.sel` / `.def`
// and the paper demo's `.id` / `.anim` (docs/formats.md, "Handle and proxy files").
//
// The files hold one entry per mesh vertex but do not name their mesh, so
// every type here keeps the path it was read from (`source`) and has a
// `validate(vertex_count)` that throws IoError naming that file when the
// entry count differs from the mesh's vertex count. Readers throw IoError
// for malformed content (message "<file>:<line>: <problem>").
//
// `.sel`  `#` comment lines, then one integer per vertex in vertex order:
//         0 = fixed, 1 = free (deformable region), 2 = handle. A comment of
//         the form `# N vertices` (as in the Botsch–Sorkine files) is checked
//         against the number of entries, which catches truncated files.
// `.def`  `#` comment lines, then a 4 × 4 row-major affine matrix M (last row
//         0 0 0 1): a handle vertex p goes to M[0:3,0:3]·p + M[0:3,3].
// `.id`   one integer per vertex. Its meaning depends on the file (see the
//         group helpers below).
// `.anim` whitespace-separated: a header
//           frames handles weights_per_handle point_lists proj_mats model_mats obj_mats
//         then `handles` rows of `weights_per_handle` (= vertex count)
//         weights — handle h is the point Σ_i w[h][i]·v_i —, then
//         `point_lists` lists of `handles` target points x y z, then
//         proj_mats + model_mats + obj_mats 4 × 4 matrices of 16 numbers each.
#pragma once

#include <qpreduce/common.h>
#include <qpreduce/deform/io/io_error.h>
#include <qpreduce/deform/mesh/mesh.h>

#include <Eigen/Core>

#include <string>
#include <vector>

namespace qpreduce::deform {

// ---- Botsch–Sorkine .sel / .def ----

enum class SelRole : int { Fixed = 0, Free = 1, Handle = 2 };

struct Selection {
  std::string source;          // the file it was read from ("" if built in code)
  std::vector<SelRole> roles;  // one per vertex

  Index size() const { return static_cast<Index>(roles.size()); }
  Index count(SelRole role) const;
  // The vertices with `role`, ascending.
  std::vector<int> vertices(SelRole role) const;
  // Throws IoError unless size() == vertex_count.
  void validate(Index vertex_count) const;
};

Selection read_sel(const std::string& path);
// The 4 × 4 matrix of a `.def` file (last row checked to be 0 0 0 1).
Eigen::Matrix4d read_def(const std::string& path);

// ---- the paper demo's .id ----

struct VertexIds {
  std::string source;
  std::vector<int> ids;  // one per vertex

  Index size() const { return static_cast<Index>(ids.size()); }
  void validate(Index vertex_count) const;
};

VertexIds read_id(const std::string& path);

// Vertices partitioned into groups. members[g] lists group g's vertices
// (ascending); group_of[v] is v's group, or −1 when v is in none;
// label[g] is the id the file uses for group g.
struct VertexGroups {
  std::vector<int> group_of;
  std::vector<std::vector<int>> members;
  std::vector<int> label;

  Index size() const { return static_cast<Index>(members.size()); }
};

// Linear proxies (`*_cluster*.id`, `*_lin*.id`): every vertex is in the group
// of its id. Groups are the distinct ids in ascending order (so ids 0..m−1
// give groups 0..m−1). A negative id is an error.
VertexGroups linear_groups_from_ids(const VertexIds& ids);
// Rotational clusters (`*_rotation*.id`, `*_c60.id`, `*_rot*_cluster.id`):
// the distinct ids ≥ 0 in ascending order, then one more cluster per
// distinct negative id (a region the user painted), in the order −1, −2, ….
VertexGroups rotation_groups_from_ids(const VertexIds& ids);
// Affine patches (`*affine.id`): 0 = free (group_of = −1), k > 0 = patch k;
// patches are the distinct k in ascending order. A negative id is an error.
VertexGroups affine_patches_from_ids(const VertexIds& ids);

// ---- the paper demo's .anim ----

struct HandleAnimation {
  std::string source;
  Index frames = 0;  // the header's `frames` field, kept as read
  // handles × vertex_count: handle h is the point Σ_i weights(h, i)·v_i.
  SparseMatrix<double> weights;
  // point_lists entries, each handles × 3: the handles' target points.
  std::vector<Vertices> targets;
  // The header's proj/model/obj matrices, filled row by row in file order.
  // No shared file has any, so their convention is unverified.
  std::vector<Eigen::Matrix4d> projection, model, object;

  Index handles() const { return weights.rows(); }
  Index vertex_count() const { return weights.cols(); }
  // The vertex of each handle, when every handle is a single vertex with
  // weight 1 (true of every shared file); throws IoError otherwise.
  std::vector<int> handle_vertices() const;
  void validate(Index vertex_count) const;
};

HandleAnimation read_anim(const std::string& path);

}  // namespace qpreduce::deform
