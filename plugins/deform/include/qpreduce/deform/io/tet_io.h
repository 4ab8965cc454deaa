// qpreduce::deform — reading and writing tetrahedral meshes: MEDIT `.mesh`
// and TetGen `.node` + `.ele` (+ `.face`).
//
// Conventions as in mesh.h: 0-based indices, the file's corner order kept
// (positive orientation means det[b − a, c − a, d − a] > 0). Readers throw
// IoError (io_error.h) rather than return partial data; a mesh without a
// vertex or without a tetrahedron is an error.
//
// MEDIT `.mesh` (ASCII; the binary `.meshb` is not supported):
//   whitespace-separated keywords and numbers, `#` comments.
//   `MeshVersionFormatted v`, `Dimension 3` (any other dimension is an
//   error), `Vertices n` then n × (x y z ref), `Triangles n` then
//   n × (i j k ref), `Tetrahedra n` then n × (i j k l ref), all 1-based;
//   the reference numbers are ignored. Sections that are read and dropped:
//   Edges, Quadrilaterals, Hexahedra, Prisms, Pyramids, Corners, Ridges,
//   RequiredVertices, RequiredEdges, RequiredTriangles, Normals,
//   NormalAtVertices, NormalAtTriangleVertices, Tangents, TangentAtVertices,
//   TangentAtEdgeVertices. Any other keyword is an error (its record size is
//   unknown, so it cannot be skipped safely). `End` stops reading.
// TetGen (ASCII, `#` comments, one record per line):
//   `.node`: header `n dim nattr nmarker` (dim must be 3), then n lines
//            `id x y z [attr…] [marker]`;
//   `.ele` : header `m npt nattr` (npt = 4, or 10 for quadratic tets of which
//            the 4 corners are kept), then m lines `id v1 … v_npt [attr…]`;
//   `.face`: header `k nmarker`, then k lines `id a b c [marker]`; optional.
//   The base of all indices (0 or 1) is the first node id of `.node`; ids
//   must then run consecutively. Attribute and marker columns are skipped,
//   but every line must have exactly the number of columns its header says.
#pragma once

#include <qpreduce/deform/io/mesh_io.h>

#include <string>

namespace qpreduce::deform {

TetMesh read_medit(const std::string& path, MeshReadInfo* info = nullptr);
// `path` names the `.node` or the `.ele` file (or the common prefix without
// extension); both must exist, and `<prefix>.face` is read when it exists.
TetMesh read_tetgen(const std::string& path, MeshReadInfo* info = nullptr);
// Dispatch on the extension (case-insensitive): .mesh → MEDIT,
// .node / .ele → TetGen.
TetMesh read_tet_mesh(const std::string& path, MeshReadInfo* info = nullptr);

// 1-based MEDIT with reference numbers 0; a `Triangles` section when F is
// not empty.
void write_medit(const std::string& path, const TetMesh& mesh);
// Writes `<prefix>.node`, `<prefix>.ele` and, when F is not empty,
// `<prefix>.face` (0-based, no attributes, no markers except the `.face`
// marker 1); `path` is the `.node` path or the prefix. The files are written
// together: a failure (a missing directory, a full disk, a file-size limit)
// leaves all the earlier ones untouched (qpreduce::write_files_atomically).
void write_tetgen(const std::string& path, const TetMesh& mesh);
// Dispatch on the extension: .mesh → MEDIT, .node → TetGen.
void write_tet_mesh(const std::string& path, const TetMesh& mesh);

}  // namespace qpreduce::deform
