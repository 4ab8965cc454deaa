// qpreduce::deform — reading and writing triangle meshes: OBJ, OFF, PLY.
//
// Every reader returns 0-based indices (see mesh.h) and throws IoError (see
// io_error.h) instead of returning partial data. A polygon with k > 3 corners
// (c0, c1, …, c_{k−1}) is fan-triangulated into (c0, c_i, c_{i+1}),
// i = 1 … k−2, which keeps its orientation and is exact for convex planar
// polygons; MeshReadInfo counts such polygons. Faces with fewer than 3
// corners, files without a vertex or without a face are errors.
//
// OBJ (Wavefront, text):
//   `v x y z [w | r g b]`  — extra numbers after x y z are ignored;
//   `f i j k …`           — each corner is `i`, `i/t`, `i/t/n` or `i//n`; only
//                            the vertex index i is used. i is 1-based; i < 0
//                            is relative (−1 = the last vertex read so far);
//                            i = 0 is an error;
//   `#` starts a comment; `vt`, `vn`, `vp`, `g`, `o`, `s`, `usemtl`, `mtllib`,
//   `l`, `p` and unknown keywords are ignored (`l` and `p` lines are counted in
//   the notes). Faces may refer to vertices defined later in the file.
// OFF (Geomview, text):
//   first token `OFF`, or with prefixes `ST`, `C`, `N` (e.g. `COFF`, `NOFF`);
//   `4OFF`, `nOFF` and `OFF BINARY` are rejected. Counts `nv nf [ne]` follow on
//   the same line or the next one; ne (edges) is ignored and may be non-zero.
//   One vertex per line: x y z, then anything (colors, normals) ignored. One
//   face per line: k i1 … ik (0-based), then anything (a color) ignored. `#`
//   starts a comment anywhere. Data after the last face is an error.
// PLY (Stanford), `format ascii 1.0` or `format binary_little_endian 1.0`
//   (`binary_big_endian` is rejected with a message saying so):
//   element `vertex` needs properties x, y, z of any scalar type (char, uchar,
//   short, ushort, int, uint, float, double or int8 … float64); other vertex
//   properties are skipped. Element `face` needs a list property named
//   `vertex_indices` or `vertex_index`, with any integer count and index type;
//   other face properties and other elements are skipped. `comment` and
//   `obj_info` header lines are ignored.
//
// Writers (OBJ, OFF, ASCII PLY, binary little-endian PLY) print every double
// in its shortest form that reads back to the same double, so a
// write-then-read round trip is exact. They check the mesh first
// (std::invalid_argument, see check_mesh) and throw IoError when the file
// cannot be written.
#pragma once

#include <qpreduce/deform/io/io_error.h>
#include <qpreduce/deform/mesh/mesh.h>

#include <string>
#include <vector>

namespace qpreduce::deform {

// What a reader did besides parsing: useful for logs, checked by the tests.
struct MeshReadInfo {
  // "obj", "off", "ply-ascii", "ply-binary-le", "medit", "tetgen".
  std::string format;
  // Polygons with more than 3 corners that were fan-triangulated.
  Index polygons_triangulated = 0;
  // Vertices no face (or, for tet meshes, no tetrahedron) refers to. They are
  // kept, so vertex indices stay those of the file.
  Index unreferenced_vertices = 0;
  // One human-readable line per thing the reader skipped or changed.
  std::vector<std::string> notes;
};

TriangleMesh read_obj(const std::string& path, MeshReadInfo* info = nullptr);
TriangleMesh read_off(const std::string& path, MeshReadInfo* info = nullptr);
TriangleMesh read_ply(const std::string& path, MeshReadInfo* info = nullptr);
// Dispatch on the extension (case-insensitive): .obj, .off, .ply.
TriangleMesh read_triangle_mesh(const std::string& path, MeshReadInfo* info = nullptr);

enum class PlyEncoding { Ascii, BinaryLittleEndian };

void write_obj(const std::string& path, const TriangleMesh& mesh);
void write_off(const std::string& path, const TriangleMesh& mesh);
// Vertices as `double x y z`, faces as `list uchar int vertex_indices`.
void write_ply(const std::string& path, const TriangleMesh& mesh,
               PlyEncoding encoding = PlyEncoding::Ascii);
// Dispatch on the extension: .obj, .off, .ply (ASCII).
void write_triangle_mesh(const std::string& path, const TriangleMesh& mesh);

}  // namespace qpreduce::deform
