// selection_handles: a selection of vertices as at most four point handles.
#include <catch2/catch.hpp>

#include "qpreduce/deform/deformer/selection_handles.h"

#include <algorithm>
#include <numeric>
#include <stdexcept>

using namespace qpreduce;
using namespace qpreduce::deform;

namespace {

// The rest position of a point handle (Σ w_i v_i, or its single vertex).
Eigen::Vector3d handle_point(const PointHandle& h, const Vertices& V) {
  if (h.weights.empty()) return V.row(h.vertices[0]).transpose();
  Eigen::Vector3d p = Eigen::Vector3d::Zero();
  for (size_t i = 0; i < h.vertices.size(); ++i) p += h.weights[i] * V.row(h.vertices[i]).transpose();
  return p;
}

// Checks what holds for every selection: 1 to 4 handles, weights summing to
// one, the handles' vertices a partition of the selection, each point inside
// the selection's bounding box, and the size-weighted mean of the points at
// the centroid.
void check_handles(const Vertices& V, const std::vector<int>& selection, const SelectionHandles& s) {
  REQUIRE(!s.points.empty());
  REQUIRE(s.points.size() <= kMaxSelectionPoints);
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(INFINITY), hi = -lo, mean = Eigen::Vector3d::Zero();
  for (int v : selection) {
    lo = lo.cwiseMin(V.row(v).transpose());
    hi = hi.cwiseMax(V.row(v).transpose());
    mean += V.row(v).transpose() / static_cast<double>(selection.size());
  }
  CHECK((s.centroid - mean).norm() <= 1e-12);
  std::vector<Index> members;
  Eigen::Vector3d weighted = Eigen::Vector3d::Zero();
  for (const PointHandle& h : s.points) {
    REQUIRE(!h.vertices.empty());
    if (h.vertices.size() == 1) {
      CHECK(h.weights.empty());
    } else {
      REQUIRE(h.weights.size() == h.vertices.size());
      CHECK(std::accumulate(h.weights.begin(), h.weights.end(), 0.0) == Approx(1.0));
    }
    const Eigen::Vector3d p = handle_point(h, V);
    CHECK((p.array() >= lo.array() - 1e-12).all());
    CHECK((p.array() <= hi.array() + 1e-12).all());
    weighted += p * static_cast<double>(h.vertices.size()) / static_cast<double>(selection.size());
    members.insert(members.end(), h.vertices.begin(), h.vertices.end());
  }
  CHECK((weighted - mean).norm() <= 1e-12);
  std::vector<Index> expected(selection.begin(), selection.end());
  std::sort(members.begin(), members.end());
  std::sort(expected.begin(), expected.end());
  CHECK(members == expected);
}

// An 6 × 5 grid in the plane z = 0.5, stretched along x.
Vertices grid() {
  Vertices V(30, 3);
  for (int i = 0; i < 30; ++i) V.row(i) << 2.0 * (i % 6), i / 6, 0.5;
  return V;
}

}  // namespace

TEST_CASE("selection_handles: up to four vertices are single-vertex handles", "[deformer][selection]") {
  const Vertices V = grid();
  for (const std::vector<int>& selection : {std::vector<int>{7}, {0, 5}, {0, 5, 24}, {0, 5, 24, 29}}) {
    const SelectionHandles s = selection_handles(V, selection);
    REQUIRE(s.points.size() == selection.size());
    for (size_t i = 0; i < selection.size(); ++i) {
      CHECK(s.points[i].vertices == std::vector<Index>{selection[i]});
      CHECK(s.points[i].weights.empty());
    }
    check_handles(V, selection, s);
  }
}

TEST_CASE("selection_handles: a planar patch becomes its four quadrant means", "[deformer][selection]") {
  const Vertices V = grid();
  std::vector<int> all(30);
  std::iota(all.begin(), all.end(), 0);
  const SelectionHandles s = selection_handles(V, all);
  REQUIRE(s.points.size() == 4);
  for (const PointHandle& h : s.points) CHECK(h.vertices.size() >= 6);
  check_handles(V, all, s);
}

TEST_CASE("selection_handles: degenerate selections still give valid handles", "[deformer][selection]") {
  const Vertices V = grid();
  SECTION("collinear") {
    const std::vector<int> row = {0, 1, 2, 3, 4, 5};  // along x
    const SelectionHandles s = selection_handles(V, row);
    CHECK(s.points.size() >= 2);  // split along the line at least
    check_handles(V, row, s);
  }
  SECTION("one point, repeated") {
    const std::vector<int> same = {8, 8, 8, 8, 8};
    const SelectionHandles s = selection_handles(V, same);
    REQUIRE(s.points.size() == 1);
    CHECK(s.points[0].weights == std::vector<double>(5, 0.2));
    check_handles(V, same, s);
  }
}

TEST_CASE("selection_handles: an empty selection or a bad vertex is refused", "[deformer][selection]") {
  const Vertices V = grid();
  CHECK_THROWS_WITH(selection_handles(V, {}), Catch::Contains("no vertex selected"));
  CHECK_THROWS_AS(selection_handles(V, {}), std::invalid_argument);
  CHECK_THROWS_AS(selection_handles(V, {3, 30}), std::invalid_argument);
  CHECK_THROWS_WITH(selection_handles(V, {-1}), Catch::Contains("vertex -1 outside [0, 30)"));
}
