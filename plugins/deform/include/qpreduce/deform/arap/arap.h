// qpreduce::deform — ARAP in libigl's terms: point handles b held at bc.
//
// For a user coming from igl::arap_precomputation + igl::arap_solve or CGAL's
// Surface_mesh_deformation: the same inputs, and the handles land where they
// are told.
//   V   n × 3 rest positions
//   F   m × 3 triangles or m × 4 tetrahedra (0-based vertex indices)
//   b   h vertex indices held (distinct, in [0, n))
//   bc  h × 3 their targets, row i for vertex b[i]
//   U   n × 3 deformed positions
//
// arap: one converged classic ARAP solve in the full space (the Refiner's
// local-global rounds, Anderson-accelerated, then Newton steps; refine.h):
// no subspace precompute, which does not pay for a single solve.
//
// ArapSolver: repeated solves with the same b. precompute builds the reduced
// deformer (deformer.h) with every vertex of b its own linear proxy
// (linear_proxies_fps with b as seeds, plus `linear_proxies` samples around
// them), so the variational subspace meets any targets at b exactly
// (paper Eq. 12–15: the proxies are the subspace's interpolation
// constraints). solve(bc) is then a reduced frame run to its fixed point;
// refine(bc) finishes it to converged classic ARAP in the full space.
// Costs against h and the break-even against arap() are in
// docs/performance.md ("Exact handles and the one-call API").
#pragma once

#include "qpreduce/deform/deformer/deformer.h"
#include "qpreduce/deform/refine/refine.h"

#include <memory>
#include <vector>

namespace qpreduce::deform {

// Converged classic ARAP with the vertices b held at bc: full-space rounds
// from the initial guess *U when it has n rows (libigl's arap_solve reads U
// the same way), else from the rest pose V; the result replaces *U.
// Throws std::invalid_argument on a bad mesh (sizes, indices, degenerate
// elements), F with other than 3 or 4 columns, b out of range or listed
// twice, bc not h × 3 or not finite, a non-finite initial guess, or invalid
// options. A failed factorization or a non-finite round comes back in the
// summary (RefineSummary::status; *U is then the last valid pose).
RefineSummary arap(const Vertices& V, const ElementsRef& F, const std::vector<Index>& b, const Vertices& bc,
                   Vertices* U, const RefineOptions& options = {});

struct ArapSolverOptions {
  // The reduced deformer. linear_proxies counts the samples added beyond the
  // vertices of b (farthest from them); rotational_proxies, energy, … as in
  // Deformer::precompute (prepare_onsite is not read: its one handle set
  // needs no preparation).
  DeformerOptions deformer;
  // Rounds of each solve: until the relative fixed-point residual is at most
  // `tolerance`, for at most `max_rounds` (Deformer::set_rounds).
  int max_rounds = 500;
  double tolerance = 1e-6;
  // The full-space finish of refine().
  RefineOptions refine;
  // The precompute is refused (status NotRun, nothing allocated) when the
  // subspace's null-space block N, 3n × d doubles with d = 3 × (h + the
  // samples), would exceed this many GB (its peak is a few times that:
  // docs/performance.md, "Exact handles"); 0: no limit. For one solve with
  // that many held vertices arap() needs no subspace.
  double max_basis_gb = 4.0;

  bool is_valid(std::string* why) const;
};

class ArapSolver {
 public:
  ArapSolver();
  ~ArapSolver();
  ArapSolver(ArapSolver&&) noexcept;
  ArapSolver& operator=(ArapSolver&&) noexcept;

  // Precomputes the reduced deformer for the handle vertices b and sets its
  // handles. Throws std::invalid_argument as arap() does, and on invalid
  // options. A numerical failure of the precompute or of the handle set
  // comes back in the summary (status and message); the solver then keeps
  // its previous precompute (not ready when there was none).
  PrecomputeSummary precompute(const Vertices& V, const ElementsRef& F, const std::vector<Index>& b,
                               const ArapSolverOptions& options = {});

  // The reduced shape for targets bc (h × 3): a frame warm-started from the
  // last solve, run to the tolerance. The rows b of *U are bc: the subspace
  // meets them exactly, and writing them from bc keeps the float
  // reconstruction's round-off (6·10⁻⁸ relative) off the handles. Throws
  // std::invalid_argument before a successful precompute, or on bc not
  // h × 3 or not finite.
  FrameSummary solve(const Vertices& bc, Vertices* U);
  // The same, into the caller's n × 3 buffer (a NumPy array) in place: no
  // copy, no allocation. Throws std::invalid_argument when `U` does not have
  // n rows.
  FrameSummary solve(const Vertices& bc, Eigen::Map<Vertices> U);
  // solve(bc), then the full-space finish from that shape to converged
  // classic ARAP (Refiner). Throws as solve.
  RefineSummary refine(const Vertices& bc, Vertices* U);

  bool ready() const;
  Index vertex_count() const;
  const std::vector<Index>& handle_vertices() const;
  // The handle set's on-site summary (Success: met exactly).
  const ConstraintSummary& handle_summary() const;
  // How far the last solve's float reconstruction put the vertices of b from
  // bc (largest distance) before their rows were written from bc: the
  // round-off the exact rows remove (NaN before any solve).
  double reconstruction_handle_error() const;
  // The reduced deformer and the model it was built for.
  const Deformer& deformer() const;
  const DeformableMesh& model() const;

 private:
  struct State;
  std::unique_ptr<State> state_;
};

}  // namespace qpreduce::deform
