// qpreduce::deform — what the deformer is given: the mesh with its proxies
// and affine patches, the handle set of the on-site step, and the targets of
// one frame.
#pragma once

#include "qpreduce/deform/energy/arap_energy.h"
#include "qpreduce/deform/mesh/mesh.h"
#include "qpreduce/deform/proxies/proxies.h"

#include <Eigen/Core>

#include <string>
#include <vector>

namespace qpreduce::deform {

// A region whose vertices move together: Fixed (stay at rest), Rigid (one
// rotation + translation), Affine (one affine map, paper Eq. 47).
enum class PatchType { Fixed, Rigid, Affine };

// What precompute needs. Exactly one of F (surface) and T (solid) is set.
struct DeformableMesh {
  Vertices V;    // n × 3 rest positions
  Triangles F;   // surface triangles, or empty
  Tetrahedra T;  // tetrahedra, or empty
  // Rotational cluster per rotation element (vertices for surfaces, tets for
  // solids). Empty: computed (compute_rotation_clusters, DeformerOptions::rotational_proxies).
  std::vector<int> clusters;
  // Linear proxies. Empty (count() == 0): farthest-point samples
  // (DeformerOptions::linear_proxies). Vertices inside patches are dropped
  // from the groups (a patch has its own 12 proxies).
  LinearProxies linear;
  // Affine patches (Eq. 47): patch_of_vertex has n entries, −1 for a free
  // vertex, else the patch index in [0, patch_types.size()). Fixed patches
  // are constrained to the rest pose at every frame; Rigid and Affine patches
  // move with their own transform (prescribed by a handle, or free).
  std::vector<int> patch_of_vertex;
  std::vector<PatchType> patch_types;

  bool is_tet() const { return T.rows() > 0; }
};

// A point handle: one vertex, or the weighted point Σ w_i v_i of a group.
struct PointHandle {
  std::vector<Index> vertices;
  std::vector<double> weights;  // empty: a single vertex (vertices.size() == 1)
};

// The handle set of the on-site step.
struct Handles {
  std::vector<PointHandle> points;
  // Non-fixed patches whose transform is prescribed each frame (a Rigid
  // patch's must be a rotation). A Rigid patch not listed here moves with
  // its own cluster's rotation (t_s = s_c), found by Phase 2.
  std::vector<Index> patches;
};

// Targets of one frame, matching the Handles given to set_handles.
struct HandleTargets {
  Vertices points;  // one row per point handle
  // One per prescribed patch: p ↦ A·p + t, stored as [A | t] (3 × 4).
  std::vector<Eigen::Matrix<double, 3, 4>> patch_transforms;
};

// A frame free of the mesh's units (Deformer::normalization, Refiner): a
// point x is x̂ = (x − centre)/scale there, with centre the middle of the
// rest pose's bounding box and scale its diagonal.
struct Normalization {
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();
  double scale = 1.0;
};
// The frame of rest positions V (n × 3); the identity frame (centre 0, scale
// 1) when V is empty, not finite or a single point (the mesh checks then
// refuse it with their own words).
Normalization normalization_of(const Vertices& V);
// `mesh` with V̂ = (V − centre)/scale, everything else as given.
DeformableMesh normalised(const DeformableMesh& mesh, const Normalization& frame);
// What a length-dependent quantity of the frame is in the given units:
// classic ARAP and E′ energies are homogeneous in the lengths, of degree 2
// on triangles (cotangent weights have no unit) and 3 on tets (weights are
// lengths): an energy of the frame times energy_unit is in the given units.
double energy_unit(const Normalization& frame, bool tet);
// Rotation elements built on the normalised rest pose, in the given units
// (weights × σ on tets, measures × σ² or σ³, normals as they are).
RotationElements in_given_units(RotationElements elements, const Normalization& frame);
// `targets` in the frame: points x̂ = (x − centre)/scale, patch transforms
// x ↦ A·x + t as x̂ ↦ A·x̂ + (A·centre + t − centre)/scale.
HandleTargets normalised(const HandleTargets& targets, const Normalization& frame);
// How far `targets` reach in that frame: the largest magnitude among the
// entries of x̂ over the points and of A and (A·centre + t − centre)/scale
// over the patch transforms (+inf when one overflows). Targets that reach
// beyond kMaxReach (mesh_check.h) are refused by Deformer::frame and qpr's
// scenario check; `where` (when not null) names the target that reaches
// farthest ("a point handle's target", "patch 3's transform").
double reach_in_frame(const HandleTargets& targets, const Normalization& frame, const Handles& handles,
                      std::string* where = nullptr);
// The refusal's words for targets that reach `reach` (beyond kMaxReach), the
// farthest named by `where`.
std::string reach_message(const std::string& where, double reach);

// Largest distance between where the handles are in `deformed` (n × 3) and
// where `targets` put them: point handles by their weighted point, patch
// handles by every vertex of the patch, Fixed patches by every vertex at rest.
double handle_residual(const DeformableMesh& model, const Handles& handles, const HandleTargets& targets,
                       const Eigen::Ref<const Vertices>& deformed);

// Linear proxies that make `handles` exact (docs/deform.md, "Exact handles"):
// every single-vertex point handle's vertex its own proxy (once, however
// often it is held; vertices inside patches are held by their patch), then
// `more` farthest-point samples around them (linear_proxies_fps with seeds).
// Set it as model.linear before Deformer::precompute: the subspace then
// meets any targets of these handles exactly (set_handles returns Success).
// Throws std::invalid_argument for a weighted group (it has no proxy of its
// own), a vertex out of range, or as linear_proxies_fps.
LinearProxies exact_handle_proxies(const DeformableMesh& model, const Handles& handles, Index more);

}  // namespace qpreduce::deform
