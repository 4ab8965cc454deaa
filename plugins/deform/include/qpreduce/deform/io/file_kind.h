// qpreduce::deform — what a mesh file holds, told by its extension the way
// the readers and writers dispatch (case-insensitive: "a.OBJ" is an OBJ).
#pragma once

#include <string>

namespace qpreduce::deform {

enum class MeshFileKind {
  Surface,  // .obj, .off, .ply (read_triangle_mesh, write_triangle_mesh)
  Tets,     // .mesh, .node, .ele (read_tet_mesh; write_tet_mesh takes .mesh and .node)
  Unknown,  // any other extension, or none
};

// The kind of mesh `path` names, from its extension alone (the file is not
// opened).
MeshFileKind mesh_file_kind(const std::string& path);

// The extension of `path` in lower case with its dot (".obj" for
// "dir/Mesh.OBJ"); "" when it has none.
std::string lower_case_extension(const std::string& path);

}  // namespace qpreduce::deform
