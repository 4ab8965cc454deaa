// qpreduce::deform — discrete geometry of triangle and tetrahedral meshes:
// cotangent Laplacians, lumped masses, areas, volumes, normals, connected
// components.
//
// Inputs are plain Eigen arrays so that any mesh type can be passed:
//   V  n × 3 vertex positions (double; RowMajor binds without a copy, a
//      ColMajor matrix is copied once into a temporary);
//   F  m × 3 triangle corners, T m × 4 tetrahedron corners (int, 0-based).
// Conventions follow mesh.h (RowMajor, counter-clockwise triangles,
// det[b − a, c − a, d − a] > 0 for tets); the functions below do not depend on
// orientation: they use |area| and |volume|.
//
// Sign convention: L is positive semi-definite,
//     L_ij = −w_ij (i ≠ j, ij an edge),   L_ii = Σ_j w_ij,
// so xᵀLx = Σ_edges w_ij (x_i − x_j)² ≥ 0 when the weights are positive, the
// rows sum to zero, and L·x = 0 for every x affine in the positions at interior
// vertices (linear precision). The weights are
//   triangles:  w_ij = ½ (cot α_ij + cot β_ij), α, β the angles opposite edge ij
//               in its (one or two) triangles;
//   tets:       w_ij = Σ_tets (1/6) · l_kl · cot θ_kl, kl the edge opposite ij in
//               the tet and θ_kl the interior dihedral angle at kl. This is the
//               P1 finite-element stiffness matrix K_ij = vol·∇φ_i·∇φ_j (which is
//               how it is computed) with L = K.
// Obtuse angles give negative weights; L is still PSD (it is a stiffness
// matrix) but not an M-matrix.
//
// Errors: std::invalid_argument at the boundary, naming the offending element:
// V not n × 3 or not finite, E with the wrong column count, an index outside
// [0, n), a repeated corner, or a degenerate element:
//   triangle: 2·area ≤ degenerate_tolerance · ℓ_max²   (ℓ_max its longest edge),
//   tet:      6·volume ≤ degenerate_tolerance · ℓ_max³,
// or a non-finite area/volume. Cotangents of such elements are not defined.
//
// Unreferenced vertices (no element uses them) get an empty row and column in
// L, zero mass and a zero normal. Callers that need M ≻ 0 (eigenproblems,
// M⁻¹) must handle them; `connected_components` flags them.
#pragma once

#include <qpreduce/common.h>

#include <Eigen/Core>

#include <vector>

namespace qpreduce::deform {

// Read-only views of the inputs. RowMajor so that mesh.h's Vertices,
// Triangles and Tetrahedra bind without copying.
using VerticesRef = Eigen::Ref<const Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>>;
using ElementsRef = Eigen::Ref<const Eigen::Matrix<int, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>>;

// Relative size below which an element counts as degenerate (see above).
// 1e-12: a triangle that thin has cotangents of order 1e12, which leave no
// digit of a double-precision factorization of L.
inline constexpr double kDefaultDegenerateTolerance = 1e-12;

// Each quantity for triangle meshes (F m × 3) and for tetrahedral ones
// (T m × 4).

// Cotangent Laplacian, n × n, PSD convention above, symmetric, rows sum to 0:
// triangles; tets (the P1 stiffness matrix).
SparseMatrix<double> cotangent_laplacian(const VerticesRef& V, const ElementsRef& F,
                                         double degenerate_tolerance = kDefaultDegenerateTolerance);
SparseMatrix<double> cotangent_laplacian_tets(const VerticesRef& V, const ElementsRef& T,
                                              double degenerate_tolerance = kDefaultDegenerateTolerance);

// Lumped mass, n entries, 0 for unreferenced vertices. Triangles:
// barycentric, area/3 to each corner, Σ = total area (barycentric, not
// Voronoi/mixed: it is positive for every non-degenerate mesh, obtuse or
// not). Tets: volume/4 to each corner, Σ = volume.
Eigen::VectorXd lumped_mass(const VerticesRef& V, const ElementsRef& F,
                            double degenerate_tolerance = kDefaultDegenerateTolerance);
Eigen::VectorXd lumped_mass_tets(const VerticesRef& V, const ElementsRef& T,
                                 double degenerate_tolerance = kDefaultDegenerateTolerance);

// Per-element measures (m entries): face areas; tet volumes
// |det[b − a, c − a, d − a]|/6 (orientation-free).
Eigen::VectorXd face_areas(const VerticesRef& V, const ElementsRef& F,
                           double degenerate_tolerance = kDefaultDegenerateTolerance);
Eigen::VectorXd tet_volumes(const VerticesRef& V, const ElementsRef& T,
                            double degenerate_tolerance = kDefaultDegenerateTolerance);

// Unit face normals (m × 3, along (b − a) × (c − a)) of a triangle mesh.
Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor> face_normals(
    const VerticesRef& V, const ElementsRef& F, double degenerate_tolerance = kDefaultDegenerateTolerance);

// Area-weighted vertex normals of a triangle mesh: n × 3,
// normalize(Σ_faces∋v area_f · n_f). Zero rows for unreferenced vertices and
// where the sum cancels exactly.
Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor> vertex_normals(
    const VerticesRef& V, const ElementsRef& F, double degenerate_tolerance = kDefaultDegenerateTolerance);

// ---- either ----

// Dispatch on E's column count: 3 → triangles, 4 → tets. L (n × n) and the
// lumped mass (n) of the same mesh. Throws for any other column count.
void laplacian_and_mass(const VerticesRef& V, const ElementsRef& E, SparseMatrix<double>* L,
                        Eigen::VectorXd* mass, double degenerate_tolerance = kDefaultDegenerateTolerance);

// Per-element measure: areas for m × 3, volumes for m × 4.
Eigen::VectorXd element_measures(const VerticesRef& V, const ElementsRef& E,
                                 double degenerate_tolerance = kDefaultDegenerateTolerance);

// ‖max − min‖ of the axis-aligned bounding box of V's rows. Throws when V is
// empty, not n × 3 or not finite.
double bounding_box_diagonal(const VerticesRef& V);

// Connected components of a mesh with n vertices and elements E (m × p, any
// p ≥ 1: triangles, tets, edges). Two elements are connected when they share a
// vertex — the coupling of the Laplacian — so L restricted to one component
// has exactly the constants as null space (for positive weights).
// Numbering: components that contain elements come first (0 ..
// element_components − 1, in order of their lowest element index), then one
// component per unreferenced vertex (in vertex order).
struct MeshComponents {
  Index count = 0;               // all components, unreferenced vertices included
  Index element_components = 0;  // components with at least one element
  std::vector<int> vertex_component;   // n entries in [0, count)
  std::vector<int> element_component;  // m entries in [0, element_components)
  std::vector<Index> unreferenced;     // vertices used by no element, ascending

  bool is_unreferenced(Index v) const { return vertex_component[v] >= element_components; }
  // Vertices of each component, ascending (count lists).
  std::vector<std::vector<Index>> vertex_lists() const;
};

// Throws std::invalid_argument for an index outside [0, n).
MeshComponents connected_components(Index n, const ElementsRef& E);

}  // namespace qpreduce::deform
