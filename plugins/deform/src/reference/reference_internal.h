// Shared by the full-space references (local_global.cpp, reference_ceres.cpp):
// model checks, anchors, and the constraint targets in the solve frame.
#pragma once

#include "qpreduce/deform/mesh/geometry.h"
#include "qpreduce/deform/reference/reference.h"

#include <functional>
#include <vector>

namespace qpreduce::deform::detail {

// The checked model: rotation elements, clusters (E′), components.
struct PreparedModel {
  Vertices V;
  bool tet = false;
  RotationElements elements;
  std::vector<int> clusters;  // per element (E′ only)
  Index d = 0;                // clusters (E′ only)
  EnergyParameters parameters;  // β = 0 for tets
  std::vector<int> patch_of_vertex;  // n entries (−1: free)
  std::vector<PatchType> patch_types;
  MeshComponents components;
  double diagonal = 0.0;
};

// Throws std::invalid_argument on an invalid model or options.
PreparedModel prepare_model(const DeformableMesh& model, const ReferenceOptions& options);

// Range checks of a handle set (vertices, weights, patch indices).
void check_handles(const PreparedModel& m, const Handles& handles);
// Sizes and finiteness of one frame's targets.
void check_targets(const Handles& handles, const HandleTargets& targets);

// Throws when a connected component has no constrained vertex (Fixed or
// prescribed patch, point handle), naming it.
void check_anchored(const PreparedModel& m, const Handles& handles);

// Prescribed patches in constraint order: the Fixed patches, then
// handles.patches; with each one's 3 × 4 transform in the solve frame
// (frameᵀ·[A | t]).
struct PatchTarget {
  Index patch;
  Eigen::Matrix<double, 3, 4> transform;
};
std::vector<PatchTarget> patch_targets(const PreparedModel& m, const Handles& handles, const HandleTargets& targets,
                                       const Eigen::Matrix3d& frame);

// The mesh and patches of `m` as a DeformableMesh (all that vertex_targets
// and handle_residual read).
DeformableMesh targets_model(const PreparedModel& m);

// S (9d, column-major 3 × 3 per cluster) from the solve frame back to the
// world: s_i ← frame·s_i.
void rotations_to_world(const Eigen::Matrix3d& frame, Eigen::VectorXd* S);

// Energy of a pose in the solve frame: arap_energy (classic) or E′.
double energy_of(const PreparedModel& m, ReferenceEnergy kind, const Vertices& Vp, const Eigen::VectorXd& Q,
                 const Eigen::VectorXd& S);

// Maps what a solve in the units-free frame `frame` (handles.h) returned to
// the given units: out->V, the energies (times `energy_unit`, handles.h),
// the handle residual and the last step. Rotations, Q and the relative
// figures have no unit.
void to_given_units(const Normalization& frame, double energy_unit, ReferenceSummary* summary, ReferenceSolution* out);

// Runs `solve` on the scene in the units-free frame of the rest pose
// (handles.h: centred, unit bounding-box diagonal) and maps its result to
// the given units (to_given_units). `initial` may be empty (the rest pose).
// Ceres' reference runs through it; LocalGlobalArap keeps its own frame.
using FrameSolve = std::function<ReferenceSummary(const DeformableMesh& model, const HandleTargets& targets,
                                                  const Vertices& initial, ReferenceSolution* out)>;
ReferenceSummary solve_in_frame(const DeformableMesh& model, const HandleTargets& targets, const Vertices& initial,
                                ReferenceSolution* out, const FrameSolve& solve);

}  // namespace qpreduce::deform::detail
