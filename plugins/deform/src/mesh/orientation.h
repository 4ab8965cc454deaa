// Consistent orientation of a triangle surface (the pre-flight, mesh_check.cpp).
// Internal to the mesh check.
#pragma once

#include "qpreduce/deform/mesh/geometry.h"

#include <array>
#include <vector>

namespace qpreduce::deform {

// An edge (a, b) that exactly two triangles share.
struct SharedEdge {
  Index a = 0, b = 0;
  Index first = 0, second = 0;  // the triangles
};

struct OrientationReport {
  // Triangles to flip for a consistent orientation: in each connected
  // component (across shared edges), the smaller of the two classes the
  // shared edges split it into (the class without the component's lowest
  // triangle on a tie). 0 when consistent.
  Index flipped = 0;
  Index disagreeing_edges = 0;       // shared edges both triangles run in the same direction
  std::vector<Index> first_flipped;  // the first triangles to flip, in index order (at most max_listed)
  // The first disagreeing edge (edge[0] → edge[1] in both triangles) and its triangles.
  std::array<Index, 2> edge{0, 0};
  Index example = 0, partner = 0;
  bool non_orientable = false;  // a component has no consistent orientation (a Möbius strip)
};

// The orientation of the triangles F (m × 3) across `shared` edges. O(m + |shared|).
OrientationReport triangle_orientation(const ElementsRef& F, const std::vector<SharedEdge>& shared, Index max_listed);

}  // namespace qpreduce::deform
