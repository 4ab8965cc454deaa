// Helpers shared by the geometry and proxy tests: small seeded meshes
// (icospheres, jittered grids and cubes of tets), the invariants every
// Laplacian, partition and Ŵ must satisfy, and a minimal OFF / .id reader for
// the shared-data tests.
#pragma once

#include <catch2/catch.hpp>

#include "qpreduce/deform/mesh/geometry.h"
#include "qpreduce/deform/proxies/proxies.h"

#include <Eigen/Dense>

#include <cmath>
#include <cstdint>
#include <fstream>
#include <limits>
#include <map>
#include <random>
#include <string>
#include <vector>

namespace proxies_test {

using qpreduce::Index;
using qpreduce::SparseMatrix;
using qpreduce::deform::LinearProxies;

using RowV = Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>;
using RowF = Eigen::Matrix<int, Eigen::Dynamic, 3, Eigen::RowMajor>;
using RowT = Eigen::Matrix<int, Eigen::Dynamic, 4, Eigen::RowMajor>;
inline constexpr double eps = std::numeric_limits<double>::epsilon();

struct Surface {
  RowV V;
  RowF F;
};
struct Solid {
  RowV V;
  RowT T;
};

// Icosphere: icosahedron with `levels` 1-to-4 subdivisions projected on the
// sphere; outward counter-clockwise faces. 10·4^levels + 2 vertices.
inline Surface icosphere(int levels, const Eigen::RowVector3d& centre = Eigen::RowVector3d::Zero(), double radius = 1.0) {
  const double t = (1.0 + std::sqrt(5.0)) / 2.0;
  std::vector<Eigen::RowVector3d> verts = {{-1, t, 0}, {1, t, 0}, {-1, -t, 0}, {1, -t, 0}, {0, -1, t}, {0, 1, t},
                                           {0, -1, -t}, {0, 1, -t}, {t, 0, -1}, {t, 0, 1}, {-t, 0, -1}, {-t, 0, 1}};
  std::vector<Eigen::Vector3i> faces = {{0, 11, 5}, {0, 5, 1},  {0, 1, 7},   {0, 7, 10}, {0, 10, 11},
                                        {1, 5, 9},  {5, 11, 4}, {11, 10, 2}, {10, 7, 6}, {7, 1, 8},
                                        {3, 9, 4},  {3, 4, 2},  {3, 2, 6},   {3, 6, 8},  {3, 8, 9},
                                        {4, 9, 5},  {2, 4, 11}, {6, 2, 10},  {8, 6, 7},  {9, 8, 1}};
  for (auto& v : verts) v.normalize();
  for (int level = 0; level < levels; ++level) {
    std::map<std::pair<int, int>, int> midpoint;
    auto mid = [&](int a, int b) {
      const auto key = std::minmax(a, b);
      auto it = midpoint.find(key);
      if (it != midpoint.end()) return it->second;
      verts.push_back((0.5 * (verts[a] + verts[b])).normalized());
      return midpoint[key] = static_cast<int>(verts.size()) - 1;
    };
    std::vector<Eigen::Vector3i> next;
    for (const auto& f : faces) {
      const int ab = mid(f[0], f[1]), bc = mid(f[1], f[2]), ca = mid(f[2], f[0]);
      next.push_back({f[0], ab, ca});
      next.push_back({f[1], bc, ab});
      next.push_back({f[2], ca, bc});
      next.push_back({ab, bc, ca});
    }
    faces = next;
  }
  Surface s;
  s.V.resize(static_cast<Index>(verts.size()), 3);
  for (std::size_t i = 0; i < verts.size(); ++i) s.V.row(static_cast<Index>(i)) = centre + radius * verts[i];
  s.F.resize(static_cast<Index>(faces.size()), 3);
  for (std::size_t i = 0; i < faces.size(); ++i) s.F.row(static_cast<Index>(i)) = faces[i].transpose();
  return s;
}

// Union of meshes (indices shifted).
inline Surface join(const Surface& a, const Surface& b) {
  Surface s;
  s.V.resize(a.V.rows() + b.V.rows(), 3);
  s.V << a.V, b.V;
  s.F.resize(a.F.rows() + b.F.rows(), 3);
  s.F << a.F, (b.F.array() + static_cast<int>(a.V.rows())).matrix();
  return s;
}

// (nx+1) × (ny+1) vertices on [0,1]² (z = 0), each square split along a
// diagonal (alternating). Interior vertices jittered by up to `jitter` cell
// sizes (seeded), so the triangles are irregular but the domain is the unit
// square (total area 1).
inline Surface planar_grid(int nx, int ny, double jitter, std::uint64_t seed) {
  Surface s;
  s.V.resize((nx + 1) * (ny + 1), 3);
  std::mt19937_64 rng(seed);
  auto u = [&rng]() { return static_cast<double>(rng() >> 11) * 0x1.0p-53 - 0.5; };
  for (int j = 0; j <= ny; ++j) {
    for (int i = 0; i <= nx; ++i) {
      const bool interior = i > 0 && i < nx && j > 0 && j < ny;
      const double dx = interior ? jitter * u() / nx : 0.0, dy = interior ? jitter * u() / ny : 0.0;
      s.V.row(i + (nx + 1) * j) << double(i) / nx + dx, double(j) / ny + dy, 0.0;
    }
  }
  s.F.resize(2 * nx * ny, 3);
  int f = 0;
  for (int j = 0; j < ny; ++j) {
    for (int i = 0; i < nx; ++i) {
      const int a = i + (nx + 1) * j, b = a + 1, c = a + (nx + 1) + 1, d = a + (nx + 1);
      if ((i + j) % 2 == 0) {
        s.F.row(f++) << a, b, c;
        s.F.row(f++) << a, c, d;
      } else {
        s.F.row(f++) << a, b, d;
        s.F.row(f++) << b, c, d;
      }
    }
  }
  return s;
}

// Unit cube [0,1]³ as an n³ lattice of cubes, each split into 6 tets around
// its main diagonal (Kuhn/Freudenthal: conforming across cubes). Interior
// vertices jittered by up to `jitter` cell sizes.
inline Solid cube_tets(int n, double jitter, std::uint64_t seed, const Eigen::RowVector3d& offset = Eigen::RowVector3d::Zero()) {
  Solid s;
  const int m = n + 1;
  auto id = [m](int i, int j, int k) { return i + m * (j + m * k); };
  s.V.resize(m * m * m, 3);
  std::mt19937_64 rng(seed);
  auto u = [&rng]() { return static_cast<double>(rng() >> 11) * 0x1.0p-53 - 0.5; };
  for (int k = 0; k < m; ++k) {
    for (int j = 0; j < m; ++j) {
      for (int i = 0; i < m; ++i) {
        const bool interior = i > 0 && i < n && j > 0 && j < n && k > 0 && k < n;
        Eigen::RowVector3d p(double(i) / n, double(j) / n, double(k) / n);
        if (interior) p += (jitter / n) * Eigen::RowVector3d(u(), u(), u());
        s.V.row(id(i, j, k)) = p + offset;
      }
    }
  }
  // The 6 monotone lattice paths from corner 000 to 111 (axis permutations).
  const int perms[6][3] = {{0, 1, 2}, {0, 2, 1}, {1, 0, 2}, {1, 2, 0}, {2, 0, 1}, {2, 1, 0}};
  s.T.resize(6 * n * n * n, 4);
  int t = 0;
  for (int k = 0; k < n; ++k) {
    for (int j = 0; j < n; ++j) {
      for (int i = 0; i < n; ++i) {
        for (const auto& p : perms) {
          int c[3] = {i, j, k};
          Eigen::Vector4i tet;
          tet[0] = id(c[0], c[1], c[2]);
          for (int step = 0; step < 3; ++step) {
            ++c[p[step]];
            tet[step + 1] = id(c[0], c[1], c[2]);
          }
          s.T.row(t++) = tet.transpose();
        }
      }
    }
  }
  return s;
}

// Vertices touched by no element and not on the boundary of [0,1]^dim.
inline std::vector<Index> interior_vertices(const RowV& V, int dims, double lo = 0.0, double hi = 1.0) {
  std::vector<Index> out;
  for (Index v = 0; v < V.rows(); ++v) {
    bool interior = true;
    for (int d = 0; d < dims; ++d) {
      interior = interior && V(v, d) > lo + 1e-9 && V(v, d) < hi - 1e-9;
    }
    if (interior) out.push_back(v);
  }
  return out;
}

inline double min_eigenvalue(const SparseMatrix<double>& L) {
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig{Eigen::MatrixXd(L)};
  return eig.eigenvalues().minCoeff();
}

inline double norm_inf(const SparseMatrix<double>& L) {
  return Eigen::MatrixXd(L).cwiseAbs().rowwise().sum().maxCoeff();
}

// Shared invariants of a Laplacian: symmetric, rows sum to zero, PSD.
inline void check_laplacian_invariants(const SparseMatrix<double>& L) {
  const double scale = norm_inf(L);
  const Index n = L.rows();
  CHECK(SparseMatrix<double>(L - SparseMatrix<double>(L.transpose())).norm() == 0.0);
  const Eigen::VectorXd row_sums = L * Eigen::VectorXd::Ones(n);
  CHECK(row_sums.cwiseAbs().maxCoeff() <= 16 * eps * scale);
  CHECK(min_eigenvalue(L) >= -8.0 * n * eps * scale);
}

// Every label in [0, count), every cluster non-empty.
inline void check_partition(const std::vector<int>& labels, Index count) {
  std::vector<Index> size(static_cast<std::size_t>(count), 0);
  for (int l : labels) {
    REQUIRE(l >= 0);
    REQUIRE(l < count);
    ++size[l];
  }
  for (Index c = 0; c < count; ++c) CHECK(size[c] > 0);
}

inline void check_rows_sum_to_one(const LinearProxies& p) {
  const Eigen::VectorXd sums = p.W * Eigen::VectorXd::Ones(p.W.cols());
  std::size_t largest = 1;
  for (const auto& g : p.groups) largest = std::max(largest, g.size());
  CHECK((sums.array() - 1.0).abs().maxCoeff() <= 2.0 * static_cast<double>(largest) * eps);
  CHECK(p.W.rows() == p.count());
}

// Minimal OFF reader for the shared-data tests (plain OFF, triangles only).
inline bool read_off(const std::string& path, Surface* s) {
  std::ifstream in(path);
  if (!in) return false;
  std::string header;
  in >> header;
  if (header != "OFF") return false;
  Index nv = 0, nf = 0, ne = 0;
  in >> nv >> nf >> ne;
  s->V.resize(nv, 3);
  for (Index v = 0; v < nv; ++v) in >> s->V(v, 0) >> s->V(v, 1) >> s->V(v, 2);
  s->F.resize(nf, 3);
  for (Index f = 0; f < nf; ++f) {
    int k = 0;
    in >> k;
    if (k != 3) return false;
    in >> s->F(f, 0) >> s->F(f, 1) >> s->F(f, 2);
  }
  return static_cast<bool>(in);
}

inline std::vector<int> read_ids(const std::string& path) {
  std::ifstream in(path);
  std::vector<int> ids;
  int id = 0;
  while (in >> id) ids.push_back(id);
  return ids;
}

}  // namespace proxies_test
