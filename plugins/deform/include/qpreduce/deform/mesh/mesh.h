// qpreduce::deform — mesh types shared by the readers, the writers and the
// deformation energies.
//
// Conventions (every reader returns data in this form, every writer expects it):
//   * indices are 0-based and lie in [0, V.rows()); file formats that count
//     from 1 (OBJ, MEDIT, 1-based TetGen) are converted on reading;
//   * V is n × 3 (one vertex per row, x y z), RowMajor so a row is contiguous;
//   * a triangle (a, b, c) is counter-clockwise when seen from the side its
//     normal (b − a) × (c − a) points to; on a closed, consistently oriented
//     surface the normals point outwards and the signed volume
//     Σ_f det[a, b, c] / 6 is positive. The readers never reorder corners, so
//     a file's orientation is kept as it is;
//   * a tetrahedron (a, b, c, d) is positively oriented when
//     det[b − a, c − a, d − a] > 0 (the TetGen and MEDIT convention). The
//     readers keep the file's order; they neither check nor flip.
#pragma once

#include <qpreduce/common.h>

#include <Eigen/Core>

namespace qpreduce::deform {

// n × 3 vertex positions.
using Vertices = Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>;
// m × 3 vertex indices of triangles.
using Triangles = Eigen::Matrix<int, Eigen::Dynamic, 3, Eigen::RowMajor>;
// m × 4 vertex indices of tetrahedra.
using Tetrahedra = Eigen::Matrix<int, Eigen::Dynamic, 4, Eigen::RowMajor>;

// A triangulated surface: V (n × 3) and F (m × 3).
struct TriangleMesh {
  Vertices V;
  Triangles F;
};

// A tetrahedral solid: V (n × 3), T (m × 4), and the boundary triangles F
// (k × 3) when the file provides them (MEDIT `Triangles`, TetGen `.face`);
// F is empty otherwise. F is kept as the file lists it (its orientation is
// whatever the file's writer chose; TetGen and the shared MEDIT files orient
// it outwards).
struct TetMesh {
  Vertices V;
  Tetrahedra T;
  Triangles F;
};

// Argument checks for the writers and for callers that build meshes in code.
//   what  the caller's name; every message starts "<what>: "
//   mesh  V (n × 3) and its elements: F (m × 3); for tets T (m × 4) and the
//         boundary F (k × 3, may be empty)
// Throws std::invalid_argument when V has a NaN/inf entry, when there is no
// vertex or no element, or when an index lies outside [0, n).
void check_mesh(const char* what, const TriangleMesh& mesh);
void check_mesh(const char* what, const TetMesh& mesh);

}  // namespace qpreduce::deform
