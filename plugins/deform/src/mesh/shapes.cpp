#include "qpreduce/deform/mesh/shapes.h"

#include <fmt/format.h>

#include <Eigen/Dense>

#include <algorithm>
#include <array>
#include <map>

#include <cmath>
#include <stdexcept>

namespace qpreduce::deform::shapes {
namespace {

// Throws std::invalid_argument unless `vertices` and `elements` (counted in
// double, so that a product of sizes cannot wrap) fit the int vertex indices
// of Triangles and Tetrahedra.
void check_index_range(const char* who, double vertices, double elements) {
  constexpr double kMaxIndex = 2147483647.0;  // 2³¹ − 1
  if (vertices > kMaxIndex || elements > kMaxIndex) {
    throw std::invalid_argument(fmt::format(
        "{}: {:.3g} vertices and {:.3g} elements, beyond the 32-bit indices of a mesh (2³¹ − 1)", who, vertices,
        elements));
  }
}

}  // namespace

TriangleMesh capped_cylinder(double radius, double height, Index around, Index rings) {
  if (around < 3 || rings < 2 || !(radius > 0) || !(height > 0)) {
    throw std::invalid_argument(fmt::format(
        "capped_cylinder: need radius > 0, height > 0, around ≥ 3, rings ≥ 2 (got {}, {}, {}, {})", radius, height,
        around, rings));
  }
  check_index_range("capped_cylinder", static_cast<double>(around) * static_cast<double>(rings) + 2.0,
                    2.0 * static_cast<double>(around) * static_cast<double>(rings));
  TriangleMesh m;
  const Index n = around * rings + 2;
  m.V.resize(n, 3);
  const double pi = std::acos(-1.0);
  for (Index j = 0; j < rings; ++j)
    for (Index v = 0; v < around; ++v) {
      const double a = 2.0 * pi * static_cast<double>(v) / static_cast<double>(around);
      m.V.row(j * around + v) << radius * std::cos(a), radius * std::sin(a),
          height * static_cast<double>(j) / static_cast<double>(rings - 1);
    }
  const int bottom = static_cast<int>(n - 2), top = static_cast<int>(n - 1);
  m.V.row(bottom) << 0.0, 0.0, 0.0;
  m.V.row(top) << 0.0, 0.0, height;
  m.F.resize(2 * around * (rings - 1) + 2 * around, 3);
  Index f = 0;
  auto id = [around](Index j, Index v) { return static_cast<int>(j * around + (v % around)); };
  for (Index j = 0; j + 1 < rings; ++j)
    for (Index v = 0; v < around; ++v) {
      // Outward normals: (p(j,v), p(j,v+1), p(j+1,v+1)) is counter-clockwise seen from outside.
      m.F.row(f++) << id(j, v), id(j, v + 1), id(j + 1, v + 1);
      m.F.row(f++) << id(j, v), id(j + 1, v + 1), id(j + 1, v);
    }
  for (Index v = 0; v < around; ++v) {
    m.F.row(f++) << bottom, id(0, v + 1), id(0, v);
    m.F.row(f++) << top, id(rings - 1, v), id(rings - 1, v + 1);
  }
  return m;
}

TetMesh box_tets(double sx, double sy, double sz, Index nx, Index ny, Index nz) {
  if (nx < 1 || ny < 1 || nz < 1 || !(sx > 0) || !(sy > 0) || !(sz > 0)) {
    throw std::invalid_argument("box_tets: sizes and cell counts must be positive");
  }
  const double cells = static_cast<double>(nx) * static_cast<double>(ny) * static_cast<double>(nz);
  const double points = static_cast<double>(nx + 1) * static_cast<double>(ny + 1) * static_cast<double>(nz + 1);
  check_index_range("box_tets", points, 6.0 * cells);
  TetMesh m;
  const Index px = nx + 1, py = ny + 1, pz = nz + 1;
  m.V.resize(px * py * pz, 3);
  auto id = [&](Index i, Index j, Index k) { return static_cast<int>(i + px * (j + py * k)); };
  for (Index k = 0; k < pz; ++k)
    for (Index j = 0; j < py; ++j)
      for (Index i = 0; i < px; ++i)
        m.V.row(id(i, j, k)) << sx * static_cast<double>(i) / static_cast<double>(nx),
            sy * static_cast<double>(j) / static_cast<double>(ny), sz * static_cast<double>(k) / static_cast<double>(nz);
  // Freudenthal: the six paths from corner 0 to corner 7 along +x, +y, +z in
  // every order give six tets sharing the main diagonal.
  static const int order[6][3] = {{0, 1, 2}, {0, 2, 1}, {1, 0, 2}, {1, 2, 0}, {2, 0, 1}, {2, 1, 0}};
  m.T.resize(6 * nx * ny * nz, 4);
  Index t = 0;
  for (Index k = 0; k < nz; ++k)
    for (Index j = 0; j < ny; ++j)
      for (Index i = 0; i < nx; ++i)
        for (const auto& o : order) {
          Index c[3] = {i, j, k};
          int tet[4];
          tet[0] = id(c[0], c[1], c[2]);
          for (int s = 0; s < 3; ++s) {
            ++c[o[s]];
            tet[s + 1] = id(c[0], c[1], c[2]);
          }
          // Orient positively.
          const Eigen::Vector3d a = m.V.row(tet[0]), b = m.V.row(tet[1]), cc = m.V.row(tet[2]), d = m.V.row(tet[3]);
          Eigen::Matrix3d E;
          E << b - a, cc - a, d - a;
          if (E.determinant() < 0) std::swap(tet[2], tet[3]);
          m.T.row(t++) << tet[0], tet[1], tet[2], tet[3];
        }
  // Boundary triangles: faces used by exactly one tet, oriented outwards.
  std::map<std::array<int, 3>, std::pair<int, std::array<int, 3>>> faces;
  static const int fidx[4][3] = {{1, 2, 3}, {0, 3, 2}, {0, 1, 3}, {0, 2, 1}};  // outward for a positive tet
  for (Index tt = 0; tt < m.T.rows(); ++tt)
    for (const auto& fi : fidx) {
      std::array<int, 3> tri = {m.T(tt, fi[0]), m.T(tt, fi[1]), m.T(tt, fi[2])};
      std::array<int, 3> key = tri;
      std::sort(key.begin(), key.end());
      auto& e = faces[key];
      ++e.first;
      e.second = tri;
    }
  Index nb = 0;
  for (const auto& kv : faces)
    if (kv.second.first == 1) ++nb;
  m.F.resize(nb, 3);
  Index f = 0;
  for (const auto& kv : faces)
    if (kv.second.first == 1) m.F.row(f++) << kv.second.second[0], kv.second.second[1], kv.second.second[2];
  return m;
}

}  // namespace qpreduce::deform::shapes
