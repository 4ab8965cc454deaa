// qpreduce::deform — the boundary surface of a tetrahedral mesh.
#pragma once

#include "qpreduce/deform/mesh/mesh.h"

namespace qpreduce::deform {

// The faces of T that belong to exactly one tetrahedron, oriented outward.
//
// Inputs:
//   T  m × 4 tetrahedra, positively oriented (det[b − a, c − a, d − a] > 0,
//      mesh.h), 0-based corners
// Output:
//   f × 3 triangles, counter-clockwise seen from outside the solid (their
//   normals point away from the tet they bound). Faces are listed in the
//   lexicographic order of their sorted corners, so the result does not
//   depend on the order of the tets.
// Preconditions: none checked; a face shared by three or more tets (a
// non-manifold mesh) is not on the boundary.
Triangles boundary_faces(const Tetrahedra& T);

}  // namespace qpreduce::deform
