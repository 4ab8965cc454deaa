// Mesh geometry (src/mesh/geometry.cpp: cotangent Laplacians, masses,
// normals, components) and the procedural shapes: invariants, hand-computed
// values and the error paths.
#include <catch2/catch.hpp>

#include "../proxies/proxies_test_util.h"  // the seeded meshes and Laplacian invariants

#include "qpreduce/deform/mesh/shapes.h"

#include <cmath>
#include <stdexcept>

using namespace qpreduce;
using namespace qpreduce::deform;
using namespace proxies_test;

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

// ---------------------------------------------------------------- shapes

TEST_CASE("procedural shapes refuse sizes whose meshes would overflow the int indices", "[geometry][shapes]") {
  // Products of sizes that wrap around 64 bits once gave a tiny mesh and writes past it.
  CHECK_THROWS_WITH(shapes::capped_cylinder(1.0, 4.0, Index(1) << 40, Index(1) << 40),
                    Catch::Contains("beyond the 32-bit indices"));
  CHECK_THROWS_WITH(shapes::capped_cylinder(1.0, 4.0, Index(1) << 31, 2), Catch::Contains("beyond the 32-bit indices"));
  CHECK_THROWS_WITH(shapes::box_tets(1.0, 1.0, 1.0, Index(1) << 22, Index(1) << 22, Index(1) << 22),
                    Catch::Contains("beyond the 32-bit indices"));
  CHECK(shapes::capped_cylinder(1.0, 4.0, 12, 6).V.rows() == 74);
  CHECK(shapes::box_tets(1.0, 1.0, 1.0, 1, 1, 1).T.rows() == 6);
}
