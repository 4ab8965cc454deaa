// boundary_faces: the outward boundary surface of a tet mesh.
#include <catch2/catch.hpp>

#include "qpreduce/deform/mesh/tet_boundary.h"

#include <Eigen/Geometry>

using namespace qpreduce;
using namespace qpreduce::deform;

namespace {

// Two positive tets sharing the face (1, 2, 3).
Vertices two_tet_vertices() {
  Vertices V(5, 3);
  V << 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 1, 1, 1;
  return V;
}

Eigen::Vector3d corner(const Vertices& V, int v) { return V.row(v).transpose(); }

// Σ over the faces of the signed volume of (origin, a, b, c): the enclosed
// volume when every face is oriented outward (divergence theorem).
double enclosed_volume(const Vertices& V, const Triangles& F) {
  double volume = 0.0;
  for (Index f = 0; f < F.rows(); ++f)
    volume += corner(V, F(f, 0)).dot(corner(V, F(f, 1)).cross(corner(V, F(f, 2)))) / 6.0;
  return volume;
}

// Every face's normal points away from the centroid of the tet it bounds.
bool outward(const Vertices& V, const Tetrahedra& T, const Triangles& F) {
  for (Index f = 0; f < F.rows(); ++f) {
    const Eigen::Vector3d a = corner(V, F(f, 0)), b = corner(V, F(f, 1)), c = corner(V, F(f, 2));
    const Eigen::Vector3d normal = (b - a).cross(c - a);
    bool found = false;
    for (Index t = 0; t < T.rows(); ++t) {
      int shared = 0;
      for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 4; ++j) shared += F(f, i) == T(t, j);
      if (shared != 3) continue;
      found = true;
      Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
      for (int j = 0; j < 4; ++j) centroid += 0.25 * corner(V, T(t, j));
      if (normal.dot((a + b + c) / 3.0 - centroid) <= 0.0) return false;
    }
    if (!found) return false;
  }
  return true;
}

}  // namespace

TEST_CASE("boundary_faces: a single tet has its four faces, oriented outward", "[mesh][boundary]") {
  const Vertices V = two_tet_vertices().topRows(4);
  Tetrahedra T(1, 4);
  T << 0, 1, 2, 3;
  const Triangles F = boundary_faces(T);
  CHECK(F.rows() == 4);
  CHECK(outward(V, T, F));
  CHECK(enclosed_volume(V, F) == Approx(1.0 / 6.0));
}

TEST_CASE("boundary_faces: two tets sharing a face have six, the shared one dropped", "[mesh][boundary]") {
  const Vertices V = two_tet_vertices();
  Tetrahedra T(2, 4);
  T << 0, 1, 2, 3, 1, 2, 3, 4;
  const Triangles F = boundary_faces(T);
  REQUIRE(F.rows() == 6);
  CHECK(outward(V, T, F));
  CHECK(enclosed_volume(V, F) == Approx(1.0 / 6.0 + 2.0 / 6.0));
  for (Index f = 0; f < F.rows(); ++f) {
    const bool shared = (F.row(f).array() == 1).any() && (F.row(f).array() == 2).any() && (F.row(f).array() == 3).any();
    CHECK_FALSE(shared);
  }
  SECTION("the result does not depend on the order of the tets") {
    Tetrahedra swapped(2, 4);
    swapped << 1, 2, 3, 4, 0, 1, 2, 3;
    CHECK(boundary_faces(swapped) == F);
  }
}

TEST_CASE("boundary_faces: no tet, no face", "[mesh][boundary]") {
  CHECK(boundary_faces(Tetrahedra(0, 4)).rows() == 0);
}
