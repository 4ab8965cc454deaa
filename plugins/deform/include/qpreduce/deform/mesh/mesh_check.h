// qpreduce::deform — pre-flight diagnostics of a mesh: everything that would
// make a precompute fail with a symptom ("not strictly convex … condition
// inf", "contains NaN") or quietly deform something other than what the user
// meant, found in one pass and named.
//
// Inputs (conventions of mesh.h):
//   V         n × 3 vertex positions;
//   E         m × 3 triangles or m × 4 tetrahedra (0-based);
//   anchored  n flags, non-zero for a vertex some handle or fixed region
//             holds; empty: anchoring is not checked (no handles known).
//
// Defects and their severity (Error: the precompute would fail or answer for
// a different mesh; Warning: it runs, but the result may not be what was
// meant):
//   no vertices / no elements                                   Error
//   non-finite coordinate; |coordinate| > max_coordinate        Error
//   corner index outside [0, n)                                 Error (nothing else is checked)
//   degenerate element: repeated corner, or
//     triangle 2·area ≤ degenerate_tolerance · ℓ_max²,
//     tet      6·volume ≤ degenerate_tolerance · ℓ_max³
//     (the rule of geometry.h: its cotangents are not defined)  Error
//   near-degenerate element: quality q < near_degenerate_quality,
//     q = (2·area/ℓ_max²) / (√3/2) for triangles,
//     q = (6·volume/ℓ_max³) · √2 for tets (1 for the regular
//     element, → 0 as it flattens; cotangents grow like 1/q)    Warning
//   inverted tet: det[b − a, c − a, d − a] < 0 while most are
//     positive (all negative: the file's opposite convention)   Warning
//   inconsistently oriented triangles: two triangles run along
//     the edge they share in the same direction; counted as the
//     triangles to flip (the smaller class in each component)   Warning
//   duplicate vertex: within duplicate_distance · diagonal of
//     a lower-numbered vertex (a seam that splits the surface)   Warning
//   unreferenced vertex (used by no element: kept, not deformed) Warning
//   … lying farther than far_distance diagonals outside the
//     bounding box of the referenced vertices                    Error
//   non-manifold edge (a triangle edge in more than 2 triangles) Warning
//   non-manifold face (a tet face in more than 2 tets)           Warning
//   non-manifold vertex: its elements, joined across the sides
//     they share, form more than one group (surfaces: more than
//     one fan, a "bow-tie"; solids: more than one piece of tets,
//     pieces touching only at the vertex or along an edge)      Warning
//   connected component no anchored vertex touches (its pose is
//     not determined: the KKT system is singular)                Error
// "diagonal" is the bounding-box diagonal of the referenced vertices with
// finite coordinates.
//
// Cost: O(n log n + m log m) time, O(n + m) memory (sorting edges, faces and
// grid cells; no per-vertex containers).
#pragma once

#include "qpreduce/deform/mesh/geometry.h"

#include <qpreduce/common.h>

#include <Eigen/Core>

#include <string>
#include <vector>

namespace qpreduce::deform {

// Coordinates up to this magnitude can be normalised and reported (the
// deformer and the refine compute on the rest pose centred and divided by
// its bounding-box diagonal σ, Normalization in deformer/handles.h, and give
// energies in the mesh's units, σ² or σ³ times the frame's): both stay
// finite (1e308 is the largest double). A limit of representation, not of
// units.
inline constexpr double kMaxCoordinate = 1e100;
// Handle targets at most this many bounding-box diagonals from the rest
// pose's centre (reach_in_frame, deformer/handles.h): the energy, which forms
// products of up to about the eighth power of the targets' distance, stays
// finite, with a margin (docs/robustness.md). Relative to the mesh, so that
// a scene gets the same verdict in any units.
inline constexpr double kMaxReach = 1e30;

enum class CheckSeverity { Warning, Error };
const char* to_string(CheckSeverity severity);  // "warning", "error"

// In the order findings are listed within one severity.
enum class MeshDefect {
  NoVertices,
  NoElements,
  NonFiniteCoordinate,
  CoordinateOverflow,
  IndexOutOfRange,
  DegenerateElement,
  FarUnreferencedVertex,
  UnanchoredComponent,
  NearDegenerateElement,
  InvertedTet,
  InconsistentOrientation,
  DuplicateVertex,
  UnreferencedVertex,
  NonManifoldEdge,
  NonManifoldFace,
  NonManifoldVertex,
};
// snake_case names for reports: "degenerate_element", "unanchored_component", …
const char* to_string(MeshDefect defect);

// One class of defect found: how many, the first offenders and a sentence
// naming the first one.
struct MeshFinding {
  MeshDefect defect = MeshDefect::NoVertices;
  CheckSeverity severity = CheckSeverity::Error;
  Index count = 0;  // offenders in all
  // What an offender is: "vertex", "triangle", "tet", "edge", "face", "component".
  std::string item;
  // The first offenders (at most MeshCheckOptions::max_listed), in index
  // order: one index for a vertex, element or component; the two or three
  // vertices of an edge or face.
  std::vector<std::vector<Index>> first;
  std::string message;  // e.g. "vertex 17 is referenced by no element and lies 1.7 bounding-box diagonals away …"
};

struct MeshCheckOptions {
  // Degenerate elements: the rule of geometry.h, with its default.
  double degenerate_tolerance = kDefaultDegenerateTolerance;
  // Near-degenerate: quality q (1 for the regular element) below this.
  // 1e-3 is a smallest angle of about 0.06° for a triangle: cotangent weights
  // near 1e3 against O(1) elsewhere, three digits of the factorization lost.
  // Still far above the degenerate rule (1e-12): a warning, not an error.
  double near_degenerate_quality = 1e-3;
  // Duplicates: vertices closer than this times the diagonal. 1e-10: far
  // below any modelled feature, far above the rounding of the file's digits.
  double duplicate_distance = 1e-10;
  // Far unreferenced vertices: farther than this many diagonals outside the
  // referenced vertices' bounding box. A vertex that far changes every
  // bounding-box–relative scale (tolerances, residuals, proxy sampling).
  double far_distance = 1.0;
  // Coordinates beyond this magnitude are an error (kMaxCoordinate).
  double max_coordinate = kMaxCoordinate;
  // Offenders listed per finding.
  Index max_listed = 10;

  // False, with the reason in *why, for a negative or non-finite tolerance
  // or a max_listed below 1.
  bool is_valid(std::string* why = nullptr) const;
};

enum class MeshCheckStatus { NotRun, Clean, Warnings, Errors };
const char* to_string(MeshCheckStatus status);  // "not run", "clean", "warnings", "errors"

// Outcome::status is Success once the diagnostics ran, with the first
// error's (else warning's) message; what they found is `verdict`.
struct MeshCheckSummary : Outcome {
  MeshCheckStatus verdict = MeshCheckStatus::NotRun;
  Index vertices = 0, elements = 0;
  int corners = 0;  // 3 (triangles) or 4 (tets)
  // Scale, over the referenced vertices with finite coordinates (zero when
  // there are none): the bounding box, its diagonal, and the shortest and
  // longest element edges.
  Eigen::Vector3d box_min = Eigen::Vector3d::Zero(), box_max = Eigen::Vector3d::Zero();
  double diagonal = 0.0, shortest_edge = 0.0, longest_edge = 0.0;
  double worst_quality = 0.0;  // smallest element quality q (see above); 0 when none was measured
  Index components = 0;        // connected components with elements
  bool anchors_checked = false;
  // Errors first, then warnings; within one severity in MeshDefect order.
  std::vector<MeshFinding> findings;
  double seconds = 0.0;

  bool has_errors() const;
  bool has_warnings() const;
  // The first finding of this severity, or nullptr.
  const MeshFinding* first(CheckSeverity severity) const;

 protected:
  void add_details(Report* out) const override;
};

// The diagnostics above. Throws std::invalid_argument when V is not n × 3,
// E has neither 3 nor 4 columns, `anchored` is neither empty nor n long, or
// the options are not valid; every defect of the data is a finding instead.
MeshCheckSummary diagnose_mesh(const VerticesRef& V, const ElementsRef& E, const std::vector<char>& anchored = {},
                               const MeshCheckOptions& options = {});

// The element components of `components` no anchored vertex touches, as an
// Error finding (count 0 when every component is held). `anchored` has one
// flag per vertex. Shared by diagnose_mesh and the scenario checks.
MeshFinding unanchored_components(const MeshComponents& components, const std::vector<char>& anchored,
                                  Index max_listed = 10);

}  // namespace qpreduce::deform
