// qpreduce — the plugin's side of the alternation (alternation.h): Phase 2
// as a projection y ← Π(g) of an input linear in (z, y) (Section 3.1), with
// the optional block structure, energy terms and proximal weights that the
// parallel, accelerated and second-order rounds use.
#pragma once

#include "qpreduce/common.h"

#include <limits>

namespace qpreduce {

// A Phase 2 projection whose input is linear in (z, y): g = G_z·z + G_y·y
// (q entries), then y ← Π(g) (Section 3.1, Phase 2).
template <typename Scalar>
class InputProjection {
 public:
  virtual ~InputProjection() = default;
  // y ← Π(g); returns ‖y_new − y_old‖. Should not allocate.
  virtual double project(const Eigen::Ref<const Vector<Scalar>>& g, Eigen::Ref<Vector<Scalar>> y) = 0;

  // Optional block structure, for parallel rounds (AlternationSettings::
  // threads). block_size() = s > 0 promises that Π acts block by block on
  // g and y of equal length (q = k): block j of y (entries [s·j, s·(j + 1)))
  // depends only on block j of g and of the old y. project_blocks then
  // updates blocks [first, last) of y only, reads no other entry of y, and
  // returns Σ‖Δy_j‖² over them; it is called concurrently on disjoint ranges.
  // Override both or neither; 0 (the default) keeps the rounds serial.
  virtual Index block_size() const { return 0; }

  // For accelerated rounds and the correction for constraints on y:
  // ½yᵀN_S y, the quadratic term in y of the energy whose Phase 2 this is
  // (for y on the manifold), and the retraction y ← the nearest point of the
  // manifold. NaN (the default): no energy terms (plain rounds only).
  virtual double quadratic_term(const Eigen::Ref<const Vector<Scalar>>& y) const {
    (void)y;
    return std::numeric_limits<double>::quiet_NaN();
  }
  virtual void retract(Eigen::Ref<Vector<Scalar>> y) const { (void)y; }

  // Proximal Phase 2, for constraints that involve y: `project` must (at
  // least) decrease its Phase 2 energy plus ½·Σ_j w_j‖y_j‖², y_j the blocks
  // of proximal_block_size() entries (one block, the whole y, when that is
  // 0), for the input it is given, which the engine forms as g + w∘y_old.
  // Projections onto a set on which each block's norm is constant
  // (rotations, unit blocks) need do nothing, which is the default; one
  // whose output's norm varies (scaled rotations) must add w_j to block j's
  // curvature. Weights ≥ 0; all 0 (or empty) restores the plain Phase 2.
  virtual Index proximal_block_size() const { return 0; }
  // Whether y is d blocks of 3 × 3 matrices (column-major, 9 entries each) on
  // SO(3) on which quadratic_term is constant, so that stiff constraints on
  // y may take second-order steps (AlternationSettings::second_order).
  virtual bool rotation_blocks() const { return false; }
  virtual void set_proximal_weights(const Eigen::Ref<const Vector<Scalar>>& weights) { (void)weights; }
  virtual double project_blocks(const Eigen::Ref<const Vector<Scalar>>& g, Eigen::Ref<Vector<Scalar>> y,
                                Index first, Index last) {
    (void)g, (void)y, (void)first, (void)last;
    return std::numeric_limits<double>::quiet_NaN();  // never called when block_size() == 0
  }
};

}  // namespace qpreduce
