// Geometry (cotangent Laplacians, masses, normals, components) and proxies
// (spectral rotational clusters, linear proxies, .id files): invariants, a few
// hand-computed values, and the error paths.
#include <catch2/catch.hpp>

#include "qpreduce/deform/mesh/geometry.h"
#include "qpreduce/deform/proxies/proxies.h"

#include <Eigen/Dense>

#include <chrono>
#include <cmath>
#include <fstream>
#include <limits>
#include <map>
#include <random>
#include <set>
#include <sstream>
#include <string>
#include <vector>

using namespace qpreduce;
using namespace qpreduce::deform;

namespace {

using RowV = Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>;
using RowF = Eigen::Matrix<int, Eigen::Dynamic, 3, Eigen::RowMajor>;
using RowT = Eigen::Matrix<int, Eigen::Dynamic, 4, Eigen::RowMajor>;
constexpr double eps = std::numeric_limits<double>::epsilon();

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
Surface icosphere(int levels, const Eigen::RowVector3d& centre = Eigen::RowVector3d::Zero(), double radius = 1.0) {
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
Surface join(const Surface& a, const Surface& b) {
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
Surface planar_grid(int nx, int ny, double jitter, std::uint64_t seed) {
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
Solid cube_tets(int n, double jitter, std::uint64_t seed, const Eigen::RowVector3d& offset = Eigen::RowVector3d::Zero()) {
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
std::vector<Index> interior_vertices(const RowV& V, int dims, double lo = 0.0, double hi = 1.0) {
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

double min_eigenvalue(const SparseMatrix<double>& L) {
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig{Eigen::MatrixXd(L)};
  return eig.eigenvalues().minCoeff();
}

double norm_inf(const SparseMatrix<double>& L) {
  return Eigen::MatrixXd(L).cwiseAbs().rowwise().sum().maxCoeff();
}

// Shared invariants of a Laplacian: symmetric, rows sum to zero, PSD.
void check_laplacian_invariants(const SparseMatrix<double>& L) {
  const double scale = norm_inf(L);
  const Index n = L.rows();
  CHECK(SparseMatrix<double>(L - SparseMatrix<double>(L.transpose())).norm() == 0.0);
  const Eigen::VectorXd row_sums = L * Eigen::VectorXd::Ones(n);
  CHECK(row_sums.cwiseAbs().maxCoeff() <= 16 * eps * scale);
  CHECK(min_eigenvalue(L) >= -8.0 * n * eps * scale);
}

// Every label in [0, count), every cluster non-empty.
void check_partition(const std::vector<int>& labels, Index count) {
  std::vector<Index> size(static_cast<std::size_t>(count), 0);
  for (int l : labels) {
    REQUIRE(l >= 0);
    REQUIRE(l < count);
    ++size[l];
  }
  for (Index c = 0; c < count; ++c) CHECK(size[c] > 0);
}

void check_rows_sum_to_one(const LinearProxies& p) {
  const Eigen::VectorXd sums = p.W * Eigen::VectorXd::Ones(p.W.cols());
  std::size_t largest = 1;
  for (const auto& g : p.groups) largest = std::max(largest, g.size());
  CHECK((sums.array() - 1.0).abs().maxCoeff() <= 2.0 * static_cast<double>(largest) * eps);
  CHECK(p.W.rows() == p.count());
}

// Minimal OFF reader for the shared-data tests (plain OFF, triangles only).
bool read_off(const std::string& path, Surface* s) {
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

std::vector<int> read_ids(const std::string& path) {
  std::ifstream in(path);
  std::vector<int> ids;
  int id = 0;
  while (in >> id) ids.push_back(id);
  return ids;
}

std::string shared_dir() {
#ifdef QPREDUCE_SHARED_DIR
  return QPREDUCE_SHARED_DIR;
#else
  return "";
#endif
}

}  // namespace

// ---------------------------------------------------------------- geometry

TEST_CASE("cotangent Laplacian and mass of a unit right-triangle pair match hand-computed values", "[geometry]") {
  RowV V(4, 3);
  V << 0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0;
  RowF F(2, 3);
  F << 0, 1, 2, 0, 2, 3;
  const Eigen::MatrixXd L = Eigen::MatrixXd(cotangent_laplacian(V, F));
  Eigen::Matrix4d expected;
  // Right angles at 1 and 3 give the diagonal 0–2 zero weight; the 45° angles
  // give each side ½·cot 45° = ½.
  expected << 1, -0.5, 0, -0.5, -0.5, 1, -0.5, 0, 0, -0.5, 1, -0.5, -0.5, 0, -0.5, 1;
  CHECK((L - expected).cwiseAbs().maxCoeff() <= 4 * eps);
  const Eigen::VectorXd m = lumped_mass(V, F);
  CHECK((m - Eigen::Vector4d(1.0 / 3, 1.0 / 6, 1.0 / 3, 1.0 / 6)).cwiseAbs().maxCoeff() <= 4 * eps);
  CHECK((face_areas(V, F).array() - 0.5).abs().maxCoeff() <= 4 * eps);
  const auto N = face_normals(V, F);
  CHECK((N.rowwise() - Eigen::RowVector3d(0, 0, 1)).cwiseAbs().maxCoeff() <= 4 * eps);
}

TEST_CASE("cotangent Laplacian of a regular tetrahedron surface has weights 1/sqrt(3)", "[geometry]") {
  RowV V(4, 3);
  V << 1, 1, 1, 1, -1, -1, -1, 1, -1, -1, -1, 1;
  RowF F(4, 3);
  F << 0, 1, 2, 0, 3, 1, 0, 2, 3, 1, 3, 2;
  const Eigen::MatrixXd L = Eigen::MatrixXd(cotangent_laplacian(V, F));
  for (int i = 0; i < 4; ++i) {
    for (int j = 0; j < 4; ++j) {
      const double want = i == j ? std::sqrt(3.0) : -1.0 / std::sqrt(3.0);
      CHECK(std::abs(L(i, j) - want) <= 8 * eps);
    }
  }
  // Edge 2√2: face area (√3/4)·8 = 2√3, each vertex in 3 faces → mass 2√3.
  const Eigen::VectorXd m = lumped_mass(V, F);
  CHECK((m.array() - 2.0 * std::sqrt(3.0)).abs().maxCoeff() <= 16 * eps);
  // Consistent outward orientation: normals point away from the centre.
  const auto N = face_normals(V, F);
  for (Index f = 0; f < 4; ++f) {
    const Eigen::RowVector3d centroid = (V.row(F(f, 0)) + V.row(F(f, 1)) + V.row(F(f, 2))) / 3.0;
    CHECK(N.row(f).dot(centroid) > 0.0);
  }
}

TEST_CASE("cotangent Laplacian invariants on closed and planar meshes", "[geometry]") {
  SECTION("icosphere") {
    const Surface s = icosphere(2);
    const SparseMatrix<double> L = cotangent_laplacian(s.V, s.F);
    check_laplacian_invariants(L);
    const Eigen::VectorXd m = lumped_mass(s.V, s.F);
    CHECK(std::abs(m.sum() - face_areas(s.V, s.F).sum()) <= 64 * eps * m.sum());
    CHECK((m.array() > 0.0).all());
    // Closed surface: Σ_f area_f n_f = 0.
    const auto N = face_normals(s.V, s.F);
    const Eigen::VectorXd A = face_areas(s.V, s.F);
    CHECK((N.transpose() * A).norm() <= 64 * eps * A.sum());
    // Area-weighted vertex normals of a sphere are nearly radial.
    const auto VN = vertex_normals(s.V, s.F);
    for (Index v = 0; v < s.V.rows(); ++v) {
      CHECK(std::abs(VN.row(v).norm() - 1.0) <= 8 * eps);
      CHECK(VN.row(v).dot(s.V.row(v).normalized()) > 0.995);
    }
  }
  SECTION("jittered planar grid: linear precision and total area") {
    const Surface s = planar_grid(9, 7, 0.4, 11);
    const SparseMatrix<double> L = cotangent_laplacian(s.V, s.F);
    check_laplacian_invariants(L);
    CHECK(std::abs(lumped_mass(s.V, s.F).sum() - 1.0) <= 64 * eps);
    const Eigen::VectorXd x = 0.3 + 1.7 * s.V.col(0).array() - 2.9 * s.V.col(1).array();
    const Eigen::VectorXd Lx = L * x;
    const std::vector<Index> interior = interior_vertices(s.V, 2);
    REQUIRE(interior.size() == 8u * 6u);
    for (Index v : interior) CHECK(std::abs(Lx[v]) <= 64 * eps * norm_inf(L));
  }
}

TEST_CASE("tet cotangent weights match hand-computed values", "[geometry][tets]") {
  SECTION("corner tet: edges at the right-angled corner weigh 1/6, the others 0") {
    RowV V(4, 3);
    V << 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1;
    RowT T(1, 4);
    T << 0, 1, 2, 3;
    const Eigen::MatrixXd L = Eigen::MatrixXd(cotangent_laplacian_tets(V, T));
    for (int j = 1; j < 4; ++j) CHECK(std::abs(L(0, j) + 1.0 / 6.0) <= 4 * eps);
    for (int i = 1; i < 4; ++i) {
      for (int j = i + 1; j < 4; ++j) CHECK(std::abs(L(i, j)) <= 4 * eps);
    }
    CHECK(std::abs(tet_volumes(V, T)[0] - 1.0 / 6.0) <= 4 * eps);
    CHECK((lumped_mass_tets(V, T).array() - 1.0 / 24.0).abs().maxCoeff() <= 4 * eps);
  }
  SECTION("regular tet of edge 2√2: w = l·cot(acos ⅓)/6 = 1/6, volume 8/3, either orientation") {
    RowV V(4, 3);
    V << 1, 1, 1, 1, -1, -1, -1, 1, -1, -1, -1, 1;
    RowT T(2, 4);
    T << 0, 1, 2, 3, 1, 0, 2, 3;  // the same tet twice, once inverted
    const Eigen::MatrixXd L = Eigen::MatrixXd(cotangent_laplacian_tets(V, T.topRows(1)));
    const Eigen::MatrixXd L2 = Eigen::MatrixXd(cotangent_laplacian_tets(V, T.bottomRows(1)));
    for (int i = 0; i < 4; ++i) {
      for (int j = 0; j < 4; ++j) CHECK(std::abs(L(i, j) - (i == j ? 0.5 : -1.0 / 6.0)) <= 8 * eps);
    }
    CHECK((L - L2).cwiseAbs().maxCoeff() <= 8 * eps);
    CHECK((tet_volumes(V, T).array() - 8.0 / 3.0).abs().maxCoeff() <= 8 * eps);
  }
}

TEST_CASE("tet cotangent Laplacian invariants: symmetric, PSD, affine functions in the kernel at interior vertices",
          "[geometry][tets]") {
  const double jitter = GENERATE(0.0, 0.3);
  CAPTURE(jitter);
  const Solid s = cube_tets(4, jitter, 5);
  const SparseMatrix<double> L = cotangent_laplacian_tets(s.V, s.T);
  check_laplacian_invariants(L);
  CHECK(std::abs(lumped_mass_tets(s.V, s.T).sum() - 1.0) <= 64 * eps);
  CHECK(std::abs(tet_volumes(s.V, s.T).sum() - 1.0) <= 64 * eps);
  const Eigen::VectorXd x = -0.7 + 1.1 * s.V.col(0).array() + 0.4 * s.V.col(1).array() - 2.3 * s.V.col(2).array();
  const Eigen::VectorXd Lx = L * x;
  const std::vector<Index> interior = interior_vertices(s.V, 3);
  REQUIRE(interior.size() == 27u);
  for (Index v : interior) CHECK(std::abs(Lx[v]) <= 64 * eps * norm_inf(L));
}

TEST_CASE("geometry rejects degenerate elements and bad input, naming the element", "[geometry][errors]") {
  RowV V(5, 3);
  V << 0, 0, 0, 1, 0, 0, 0, 1, 0, 2, 0, 0, 0, 0, 1;
  RowF F(2, 3);
  F << 0, 1, 2, 0, 1, 3;  // face 1 is collinear
  CHECK_THROWS_WITH(cotangent_laplacian(V, F), Catch::Contains("face 1") && Catch::Contains("degenerate"));
  CHECK_THROWS_WITH(lumped_mass(V, F), Catch::Contains("face 1"));
  RowF repeated(1, 3);
  repeated << 0, 2, 2;
  CHECK_THROWS_WITH(face_areas(V, repeated), Catch::Contains("face 0") && Catch::Contains("repeated"));
  RowF out_of_range(1, 3);
  out_of_range << 0, 1, 7;
  CHECK_THROWS_WITH(cotangent_laplacian(V, out_of_range), Catch::Contains("outside [0, 5)"));
  RowV nan = V;
  nan(2, 1) = std::numeric_limits<double>::quiet_NaN();
  CHECK_THROWS_AS(cotangent_laplacian(nan, F.topRows(1)), std::invalid_argument);
  RowT T(2, 4);
  T << 0, 1, 2, 4, 0, 1, 2, 3;  // tet 1 is flat (z = 0)
  CHECK_THROWS_WITH(cotangent_laplacian_tets(V, T), Catch::Contains("tet 1") && Catch::Contains("degenerate"));
  CHECK_THROWS_WITH(lumped_mass_tets(V, T), Catch::Contains("tet 1"));
  CHECK_THROWS_AS(cotangent_laplacian_tets(V, F), std::invalid_argument);  // 3 columns
  CHECK_THROWS_AS(bounding_box_diagonal(RowV(0, 3)), std::invalid_argument);
}

TEST_CASE("unreferenced vertices: zero mass, empty Laplacian row, their own flagged components", "[geometry]") {
  Surface s = join(icosphere(1), icosphere(1, Eigen::RowVector3d(3, 0, 0)));
  const Index n0 = s.V.rows();
  s.V.conservativeResize(n0 + 1, 3);
  s.V.row(n0) << 10, 10, 10;
  const SparseMatrix<double> L = cotangent_laplacian(s.V, s.F);
  CHECK(L.col(n0).norm() == 0.0);
  CHECK(lumped_mass(s.V, s.F)[n0] == 0.0);
  CHECK(vertex_normals(s.V, s.F).row(n0).norm() == 0.0);
  const MeshComponents c = connected_components(s.V.rows(), s.F);
  CHECK(c.count == 3);
  CHECK(c.element_components == 2);
  REQUIRE(c.unreferenced.size() == 1u);
  CHECK(c.unreferenced[0] == n0);
  CHECK(c.is_unreferenced(n0));
  CHECK_FALSE(c.is_unreferenced(0));
  const auto lists = c.vertex_lists();
  CHECK(lists[0].size() == 42u);
  CHECK(lists[1].size() == 42u);
  CHECK(c.vertex_component[0] == 0);
  CHECK(c.vertex_component[42] == 1);
  for (Index f = 0; f < s.F.rows(); ++f) CHECK(c.element_component[f] == (f < 80 ? 0 : 1));
  CHECK(std::abs(bounding_box_diagonal(s.V) - Eigen::Vector3d(11, 11, 11).norm()) <= 8 * eps * 20);
}

// ---------------------------------------------------------------- k-means

TEST_CASE("k-means is deterministic for a seed and returns exactly k non-empty clusters", "[kmeans]") {
  std::mt19937_64 rng(3);
  Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> X(300, 4);
  for (Index i = 0; i < X.rows(); ++i) {
    for (Index j = 0; j < X.cols(); ++j) X(i, j) = static_cast<double>(rng() >> 11) * 0x1.0p-53 + (i % 5);
  }
  const Index k = GENERATE(1, 5, 17, 300);
  CAPTURE(k);
  KMeansOptions o;
  o.seed = 42;
  const KMeansResult a = kmeans(X, k, o), b = kmeans(X, k, o);
  CHECK(a.labels == b.labels);
  check_partition(a.labels, k);
  CHECK(a.converged);
  CHECK(a.centres.rows() == k);
  if (k == 300) CHECK(a.objective == 0.0);
  // The objective is the sum of squared distances to the reported centres.
  double objective = 0.0;
  for (Index i = 0; i < X.rows(); ++i) objective += (X.row(i) - a.centres.row(a.labels[i])).squaredNorm();
  CHECK(std::abs(objective - a.objective) <= 1e-12 * (1.0 + objective));
  if (k == 5) {
    // Five well-separated blobs (offsets 0..4 in every coordinate): recovered.
    for (Index i = 0; i < X.rows(); ++i) CHECK(a.labels[i] == a.labels[i % 5]);
  }
  if (k == 17) {
    // Different seeds give valid (possibly different) partitions.
    o.seed = 43;
    check_partition(kmeans(X, k, o).labels, k);
  }
}

TEST_CASE("k-means with coincident points still gives k non-empty clusters; bad k throws", "[kmeans][errors]") {
  const Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> X =
      Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>::Ones(10, 2);
  check_partition(kmeans(X, 4).labels, 4);
  CHECK_THROWS_WITH(kmeans(X, 11), Catch::Contains("[1, 10]"));
  CHECK_THROWS_AS(kmeans(X, 0), std::invalid_argument);
}

// ---------------------------------------------------------------- spectral

TEST_CASE("Laplace–Beltrami eigenpairs: Spectra shift-invert agrees with the dense solver", "[spectral]") {
  const Backend backend = GENERATE(Backend::Cholmod, Backend::SimplicialLDLT);
  CAPTURE(to_string(backend));
  const Surface s = icosphere(3);  // 642 vertices: above dense_max_size
  const SparseMatrix<double> L = cotangent_laplacian(s.V, s.F);
  const Eigen::VectorXd m = lumped_mass(s.V, s.F);
  SpectralOptions o;
  o.backend = backend;
  Eigenpairs sparse, dense;
  const SpectralSummary ss = laplacian_eigenpairs(L, m, 10, -0.01, o, &sparse);
  INFO(ss.brief_report());
  REQUIRE(ss.ok());
  CHECK(ss.lanczos_operations > 0);
  CHECK(ss.max_relative_residual < 1e-10);
  o.dense_max_size = 1000;
  const SpectralSummary ds = laplacian_eigenpairs(L, m, 10, -0.01, o, &dense);
  REQUIRE(ds.ok());
  CHECK(ds.lanczos_operations == 0);
  CHECK((sparse.values - dense.values).cwiseAbs().maxCoeff() <= 1e-9 * dense.values.maxCoeff());
  // M-orthonormal.
  const Eigen::MatrixXd G = sparse.vectors.transpose() * m.asDiagonal() * sparse.vectors;
  CHECK((G - Eigen::MatrixXd::Identity(10, 10)).cwiseAbs().maxCoeff() <= 1e-9);
  // Unit sphere: λ_0 = 0, then l(l+1) with multiplicity 2l+1 (2, then 6), up to discretisation.
  CHECK(std::abs(sparse.values[0]) <= 1e-9);
  for (int j = 1; j <= 3; ++j) CHECK(sparse.values[j] == Approx(2.0).epsilon(0.02));
  for (int j = 4; j <= 8; ++j) CHECK(sparse.values[j] == Approx(6.0).epsilon(0.03));
}

TEST_CASE("laplacian_eigenpairs reports non-convergence as a status, not silently", "[spectral][errors]") {
  const Surface s = icosphere(3);
  const SparseMatrix<double> L = cotangent_laplacian(s.V, s.F);
  const Eigen::VectorXd m = lumped_mass(s.V, s.F);
  SpectralOptions o;
  o.max_restarts = 1;
  o.min_lanczos_vectors = 2;
  o.tolerance = 1e-300;
  Eigenpairs pairs;
  pairs.values = Eigen::VectorXd::Constant(1, 7.0);
  const SpectralSummary summary = laplacian_eigenpairs(L, m, 10, -0.01, o, &pairs);
  CHECK(summary.status == Status::NumericalFailure);
  CHECK_THAT(summary.message, Catch::Contains("did not converge"));
  CHECK(pairs.values.size() == 1);  // untouched
  CHECK_THROWS_AS(laplacian_eigenpairs(L, m, 10, 0.5, SpectralOptions{}, &pairs), std::invalid_argument);
  CHECK_THROWS_AS(laplacian_eigenpairs(L, m, 700, -0.01, SpectralOptions{}, &pairs), std::invalid_argument);

  // And through the clustering entry point.
  ClusterOptions co;
  co.spectral = o;
  Clustering clusters;
  const ClusterSummary cs = compute_rotation_clusters(s.V, s.F, ClusterElement::Vertex, 8, co, &clusters);
  CHECK(cs.status == Status::NumericalFailure);
  CHECK_FALSE(cs.message.empty());
  CHECK(clusters.labels.empty());
}

// ---------------------------------------------------------------- rotational clusters

TEST_CASE("spectral rotation clusters: exact count, non-empty, deterministic, never spanning components",
          "[clusters]") {
  // A big sphere (642 vertices, Spectra path) and a small one (162, dense path).
  const Surface s = join(icosphere(3), icosphere(2, Eigen::RowVector3d(4, 0, 0), 0.5));
  const Index d = GENERATE(2, 9, 27);
  CAPTURE(d);
  ClusterOptions o;
  Clustering a, b;
  const ClusterSummary sa = compute_rotation_clusters(s.V, s.F, ClusterElement::Vertex, d, o, &a);
  INFO(sa.brief_report());
  REQUIRE(sa.ok());
  REQUIRE(compute_rotation_clusters(s.V, s.F, ClusterElement::Vertex, d, o, &b).ok());
  CHECK(a.labels == b.labels);
  CHECK(a.count == d);
  REQUIRE(a.labels.size() == static_cast<std::size_t>(s.V.rows()));
  check_partition(a.labels, d);
  const MeshComponents comps = connected_components(s.V.rows(), s.F);
  REQUIRE(a.component_of_cluster.size() == static_cast<std::size_t>(d));
  for (Index v = 0; v < s.V.rows(); ++v) CHECK(a.component_of_cluster[a.labels[v]] == comps.vertex_component[v]);
  // The sphere with 4× the area gets most clusters.
  const Index on_big = std::count(a.component_of_cluster.begin(), a.component_of_cluster.end(), 0);
  CHECK(on_big >= d - on_big);
  CHECK(sa.spectral.max_relative_residual < 1e-8);
  // Clusters on a sphere are spatially coherent: each cluster's vertices lie
  // in a cap much smaller than the sphere (for d ≥ 9).
  if (d >= 9) {
    const auto members = cluster_members(a.labels, d);
    for (Index c = 0; c < d; ++c) {
      Eigen::RowVector3d mean = Eigen::RowVector3d::Zero();
      for (Index v : members[c]) mean += s.V.row(v);
      mean /= static_cast<double>(members[c].size());
      double spread = 0.0;
      for (Index v : members[c]) spread = std::max(spread, (s.V.row(v) - mean).norm());
      const double radius = a.component_of_cluster[c] == 0 ? 1.0 : 0.5;
      CHECK(spread < 1.5 * radius);
    }
  }
  // Another seed: still a valid partition of the same size.
  o.kmeans.seed = 7;
  Clustering c;
  REQUIRE(compute_rotation_clusters(s.V, s.F, ClusterElement::Vertex, d, o, &c).ok());
  check_partition(c.labels, d);
}

TEST_CASE("rotation clusters: count errors and unreferenced vertices", "[clusters][errors]") {
  Surface s = join(icosphere(1), icosphere(1, Eigen::RowVector3d(3, 0, 0)));
  const Index n0 = s.V.rows();
  s.V.conservativeResize(n0 + 1, 3);
  s.V.row(n0) << 3.5, 0, 0;  // nearest referenced vertex is on the second sphere
  ClusterOptions o;
  Clustering out;
  CHECK_THROWS_WITH(compute_rotation_clusters(s.V, s.F, ClusterElement::Vertex, 1, o, &out),
                    Catch::Contains("cannot cover 2 connected components"));
  CHECK_THROWS_WITH(compute_rotation_clusters(s.V, s.F, ClusterElement::Vertex, n0 + 1, o, &out),
                    Catch::Contains("[1, 84]"));
  CHECK_THROWS_AS(compute_rotation_clusters(s.V, s.F, ClusterElement::Element, 161, o, &out), std::invalid_argument);
  REQUIRE(compute_rotation_clusters(s.V, s.F, ClusterElement::Vertex, 6, o, &out).ok());
  check_partition(out.labels, 6);
  CHECK(out.component_of_cluster[out.labels[n0]] == 1);
  // d = number of elements: singletons.
  REQUIRE(compute_rotation_clusters(s.V, s.F, ClusterElement::Vertex, n0, o, &out).ok());
  check_partition(out.labels, n0);
}

TEST_CASE("rotation clusters of tets: one label per tet (barycentre embeddings) or per vertex", "[clusters][tets]") {
  Solid a = cube_tets(5, 0.2, 1);                                    // 750 tets, 216 vertices
  const Solid b = cube_tets(2, 0.0, 2, Eigen::RowVector3d(3, 0, 0));  // a second component
  Solid s;
  s.V.resize(a.V.rows() + b.V.rows(), 3);
  s.V << a.V, b.V;
  s.T.resize(a.T.rows() + b.T.rows(), 4);
  s.T << a.T, (b.T.array() + static_cast<int>(a.V.rows())).matrix();
  const MeshComponents comps = connected_components(s.V.rows(), s.T);
  REQUIRE(comps.count == 2);
  ClusterOptions o;
  Clustering per_tet, per_vertex;
  const ClusterSummary st = compute_rotation_clusters(s.V, s.T, ClusterElement::Element, 12, o, &per_tet);
  INFO(st.brief_report());
  REQUIRE(st.ok());
  REQUIRE(per_tet.labels.size() == static_cast<std::size_t>(s.T.rows()));
  check_partition(per_tet.labels, 12);
  for (Index t = 0; t < s.T.rows(); ++t) {
    CHECK(per_tet.component_of_cluster[per_tet.labels[t]] == comps.element_component[t]);
  }
  REQUIRE(compute_rotation_clusters(s.V, s.T, ClusterElement::Vertex, 12, o, &per_vertex).ok());
  REQUIRE(per_vertex.labels.size() == static_cast<std::size_t>(s.V.rows()));
  check_partition(per_vertex.labels, 12);
}

TEST_CASE(".id clusters: every negative id is one painted cluster, relabelled after the others", "[clusters][ids]") {
  const std::vector<int> ids = {3, -1, 0, -2, 3, -1, 5, 0};
  const IdClustering c = clusters_from_ids(ids, 8);
  CHECK(c.count == 5);
  CHECK(c.painted == 2);
  CHECK(c.original_id == std::vector<int>({0, 3, 5, -1, -2}));
  CHECK(c.labels == std::vector<int>({1, 3, 0, 4, 1, 3, 2, 0}));
  check_partition(c.labels, c.count);
  CHECK_THROWS_WITH(clusters_from_ids(ids, 9), Catch::Contains("expected 9, got 8"));
  CHECK_THROWS_AS(clusters_from_ids({}, 0), std::invalid_argument);

  const LinearProxies p = linear_proxies_from_ids(ids, 8);
  CHECK(p.count() == 5);
  check_rows_sum_to_one(p);
  CHECK(p.groups[1] == std::vector<Index>({0, 4}));
  CHECK(Eigen::MatrixXd(p.W)(1, 0) == 0.5);
}

// ---------------------------------------------------------------- linear proxies

TEST_CASE("farthest-point samples cover every component and are deterministic", "[linear][fps]") {
  Surface s = join(icosphere(2), icosphere(1, Eigen::RowVector3d(3, 0, 0), 0.3));
  const Index n0 = s.V.rows();
  s.V.conservativeResize(n0 + 1, 3);
  s.V.row(n0) << 9, 9, 9;  // unreferenced: its own component
  const MeshComponents comps = connected_components(s.V.rows(), s.F);
  REQUIRE(comps.count == 3);
  CHECK_THROWS_WITH(linear_proxies_fps(s.V, s.F, 2),
                    Catch::Contains("2 samples cannot cover 3 connected components") &&
                        Catch::Contains("1 of them unreferenced"));
  CHECK_THROWS_AS(linear_proxies_fps(s.V, s.F, s.V.rows() + 1), std::invalid_argument);
  for (Index m : {Index(3), Index(20), s.V.rows()}) {
    CAPTURE(m);
    const LinearProxies p = linear_proxies_fps(s.V, s.F, m);
    const LinearProxies q = linear_proxies_fps(s.V, s.F, m);
    CHECK(p.groups == q.groups);
    REQUIRE(p.count() == m);
    check_rows_sum_to_one(p);
    std::set<Index> distinct;
    std::set<int> covered;
    for (const auto& g : p.groups) {
      REQUIRE(g.size() == 1u);
      distinct.insert(g[0]);
      covered.insert(comps.vertex_component[g[0]]);
    }
    CHECK(distinct.size() == static_cast<std::size_t>(m));
    CHECK(covered.size() == 3u);
    std::string why;
    CHECK(proxies_cover_components(p, comps, &why));
  }
  // Spread: 12 samples on the 162-vertex sphere (alone) are far apart.
  const Surface sphere = icosphere(2);
  const LinearProxies p = linear_proxies_fps(sphere.V, sphere.F, 12);
  double closest = 10.0;
  for (Index i = 0; i < 12; ++i) {
    for (Index j = 0; j < i; ++j) {
      closest = std::min(closest, (sphere.V.row(p.groups[i][0]) - sphere.V.row(p.groups[j][0])).norm());
    }
  }
  CHECK(closest > 0.7);  // the 12 icosahedron vertices are 1.05 apart
}

TEST_CASE("vertex groups: exact count, non-empty, within components, rows of W sum to one", "[linear][groups]") {
  Surface s = join(icosphere(3), icosphere(2, Eigen::RowVector3d(4, 0, 0), 0.5));
  const Index n0 = s.V.rows();
  s.V.conservativeResize(n0 + 1, 3);
  s.V.row(n0) << 9, 9, 9;
  const MeshComponents comps = connected_components(s.V.rows(), s.F);
  const GroupSpace space = GENERATE(GroupSpace::Spectral, GroupSpace::Positions);
  CAPTURE(static_cast<int>(space));
  ClusterOptions o;
  CHECK_THROWS_WITH(linear_proxies_groups(s.V, s.F, 2, space, o, nullptr), Catch::Contains("out is null"));
  LinearProxies a, b;
  CHECK_THROWS_WITH(linear_proxies_groups(s.V, s.F, 2, space, o, &a), Catch::Contains("cannot cover 3"));
  const ClusterSummary sa = linear_proxies_groups(s.V, s.F, 30, space, o, &a);
  INFO(sa.brief_report());
  REQUIRE(sa.ok());
  REQUIRE(linear_proxies_groups(s.V, s.F, 30, space, o, &b).ok());
  CHECK(a.groups == b.groups);
  REQUIRE(a.count() == 30);
  check_rows_sum_to_one(a);
  std::vector<Index> seen(static_cast<std::size_t>(s.V.rows()), 0);
  for (const auto& g : a.groups) {
    REQUIRE_FALSE(g.empty());
    for (Index v : g) {
      ++seen[v];
      CHECK(comps.vertex_component[v] == comps.vertex_component[g[0]]);
    }
  }
  for (Index v = 0; v < s.V.rows(); ++v) CHECK(seen[v] == 1);  // a partition of the vertices
  std::string why;
  CHECK(proxies_cover_components(a, comps, &why));
}

TEST_CASE("proxies_cover_components detects uncovered and jointly pinned components", "[linear][errors]") {
  const Surface s = join(icosphere(1), icosphere(1, Eigen::RowVector3d(3, 0, 0)));
  const MeshComponents comps = connected_components(s.V.rows(), s.F);
  std::string why;
  CHECK_FALSE(proxies_cover_components(linear_proxies_from_groups({{0}, {5}}, s.V.rows()), comps, &why));
  CHECK_THAT(why, Catch::Contains("component 1 has no linear proxy"));
  // One group averaging vertices of both spheres pins only their sum.
  CHECK_FALSE(proxies_cover_components(linear_proxies_from_groups({{0, 50}}, s.V.rows()), comps, &why));
  CHECK_THAT(why, Catch::Contains("1 of 2"));
  CHECK(proxies_cover_components(linear_proxies_from_groups({{0, 50}, {1}}, s.V.rows()), comps, &why));
  CHECK_THROWS_WITH(linear_proxies_from_groups({{0, 0}}, s.V.rows()), Catch::Contains("twice"));
  CHECK_THROWS_WITH(linear_proxies_from_groups({{}}, s.V.rows()), Catch::Contains("empty"));
}

// ---------------------------------------------------------------- shared data

TEST_CASE("shared data: bunny spectral clusters and the paper's cactus .id file", "[clusters][data]") {
  const std::string dir = shared_dir();
  Surface bunny;
  if (dir.empty() || !read_off(dir + "/data/meshes/bunny.off", &bunny)) {
    WARN("shared data not found; skipped");
    return;
  }
  ClusterOptions o;
  Clustering c;
  const ClusterSummary summary = compute_rotation_clusters(bunny.V, bunny.F, ClusterElement::Vertex, 27, o, &c);
  INFO(summary.brief_report());
  REQUIRE(summary.ok());
  check_partition(c.labels, 27);
  CHECK(summary.spectral.max_relative_residual < 1e-8);
  const MeshComponents comps = connected_components(bunny.V.rows(), bunny.F);
  for (Index v = 0; v < bunny.V.rows(); ++v) {
    CHECK(c.component_of_cluster[c.labels[v]] == comps.vertex_component[v]);
  }
  const LinearProxies fps = linear_proxies_fps(bunny.V, bunny.F, 30);
  check_rows_sum_to_one(fps);
  std::string why;
  CHECK(proxies_cover_components(fps, comps, &why));

  Surface cactus;
  REQUIRE(read_off(dir + "/data/meshes/botsch-sorkine/cactus.off", &cactus));
  const IdClustering ids =
      clusters_from_ids(read_ids(dir + "/data/paper-examples/cactus/cactus_rotation25.id"), cactus.V.rows());
  CHECK(ids.count == 27);
  CHECK(ids.painted == 2);
  check_partition(ids.labels, ids.count);
  const LinearProxies groups =
      linear_proxies_from_ids(read_ids(dir + "/data/paper-examples/cactus/cactus_cluster27.id"), cactus.V.rows());
  CHECK(groups.count() == 27);
  check_rows_sum_to_one(groups);
  CHECK(proxies_cover_components(groups, connected_components(cactus.V.rows(), cactus.F), &why));
}

// Timing of the 40k-vertex case (hidden: run with `deform_proxies_tests "[perf]" -d yes`).
TEST_CASE("perf: bumpy plane (40k vertices) into 27 rotation clusters", "[.][perf]") {
  Surface plane;
  if (!read_off(shared_dir() + "/data/meshes/botsch-sorkine/bumpy_plane.off", &plane)) {
    WARN("shared data not found; skipped");
    return;
  }
  ClusterOptions o;
  Clustering c;
  const auto start = std::chrono::steady_clock::now();
  const ClusterSummary summary = compute_rotation_clusters(plane.V, plane.F, ClusterElement::Vertex, 27, o, &c);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  INFO(summary.brief_report());
  INFO("wall " << seconds << " s");
  REQUIRE(summary.ok());
  check_partition(c.labels, 27);
  // Timing is reported, not asserted (shared machines make wall time noisy).
  WARN(summary.brief_report() << " | wall " << seconds << " s");
}
