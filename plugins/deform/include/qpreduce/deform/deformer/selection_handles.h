// qpreduce::deform — point handles standing in for a selection of vertices
// (the viewer's "make handle": the selection is grabbed as a rigid piece).
#pragma once

#include "qpreduce/deform/deformer/handles.h"

#include <Eigen/Core>

#include <cstddef>
#include <vector>

namespace qpreduce::deform {

// Most point handles a selection becomes: four points off a common plane fix
// a rigid frame, with at most 12 constraint rows per selection.
inline constexpr std::size_t kMaxSelectionPoints = 4;

// A selection as point handles, and its mean (the pivot of a rigid grab).
struct SelectionHandles {
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();  // mean of the selected rest positions
  std::vector<PointHandle> points;                     // 1 to kMaxSelectionPoints handles
};

// Builds at most kMaxSelectionPoints point handles for a selection.
//
// Inputs:
//   V          n × 3 rest positions
//   selection  s ≥ 1 vertex indices in [0, n) (the order is kept)
// Output:
//   s ≤ 4: one single-vertex handle per selected vertex (empty weights).
//   s > 4: the selection is split into quadrants by the signs of its
//   positions' offsets from the centroid along its two main axes (the
//   eigenvectors of the 3 × 3 scatter matrix with the two largest
//   eigenvalues); every non-empty quadrant gives the weighted point at its
//   mean (equal weights 1/|quadrant|, summing to 1). A degenerate selection
//   (collinear, or all at one point) still gives 1 to 4 handles.
// Throws std::invalid_argument when the selection is empty or names a vertex
// outside [0, n).
SelectionHandles selection_handles(const Vertices& V, const std::vector<int>& selection);

}  // namespace qpreduce::deform
