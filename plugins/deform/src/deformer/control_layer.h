// Internal: the control layer's map from vertex coordinates to controls,
// shared by the deformer (Model::control_row) and the local-global reference
// (LocalGlobalState::control_row), so both build the same P (V′ = P·u).
#pragma once

#include "qpreduce/deform/mesh/mesh.h"

#include <Eigen/SparseCore>

#include <vector>

namespace qpreduce::deform::detail {

// Appends to *t the control-layer entries of coordinate a (0, 1 or 2) of
// vertex v, scaled by `scale`, in column `col`: the entries (row, col, value)
// such that V′(v, a) = Σ value·u(row) (docs/deform.md, "The control layer";
// Appendix, Eq. 47). A free vertex has 3 controls, its position: one entry
// at control_of_free[v] + a. A vertex of patch p moves as v′ = t_p·v + d_p,
// whose 12 controls (t_p row-major, then d_p) start at patch_base + 12·p:
// four entries, rest(v, 0..2) for row a of t_p and 1 for d_p(a).
//   patch_of_vertex  n entries, −1 for a free vertex; empty: every vertex free
//   rest             n × 3 rest positions
//   control_of_free  n entries, the first control row of a free vertex
//   patch_base       the first control row of the patches (3·n_free)
inline void add_control_row(const std::vector<int>& patch_of_vertex, const Vertices& rest,
                            const std::vector<Index>& control_of_free, Index patch_base, Index v, int a,
                            double scale, Index col, std::vector<Eigen::Triplet<double>>* t) {
  const int p = patch_of_vertex.empty() ? -1 : patch_of_vertex[v];
  if (p < 0) {
    t->emplace_back(control_of_free[v] + a, col, scale);
    return;
  }
  const Index base = patch_base + 12 * p;
  for (int c = 0; c < 3; ++c) t->emplace_back(base + 3 * a + c, col, scale * rest(v, c));
  t->emplace_back(base + 9 + a, col, scale);
}

}  // namespace qpreduce::deform::detail
