// qpreduce — how a demand's constraints AᵀX = b are met in the subspace
// (SubspaceSolver::set_constraints, Alternation::setup): hard (Eq. 17) or
// soft (Eq. 18), the rank and round-off tolerances, the fast path, and the
// summary of one on-site step (rank, condition, the path taken).
#pragma once

#include "qpreduce/common.h"

#include <string>

namespace qpreduce {

struct ConstraintOptions {
  // false: hard constraints (Eq. 17); true: soft constraints (Eq. 18).
  bool soft = false;
  // Soft-constraint weight δ (Eq. 18). Relative to H_r's scale: the system
  // solved is H_r + 2·δ·A_rᵀA_r, so δ ≫ ‖H_r‖/‖A_r‖² approaches hard constraints.
  double delta = 1e3;
  // Singular values of Ā (and eigenvalues of the reduced Hessian on the
  // constraint set) below rank_tolerance × the largest count as zero.
  double rank_tolerance = 1e-10;
  // set_constraints(A) only: entries of A_r = AᵀB with |A_r(i,j)| ≤
  // drop_tolerance·‖a_i‖₂·‖B_j‖₂ (a_i: column i of A, B_j: column j of B)
  // are round-off and set to exactly zero, so that in-design demands given as
  // a sparse A get the sparse A_r = [A_cᵀ 0] and the factored path
  // (docs/engine.md, "Round-off in A_r = AᵀB"). 0 keeps every entry. In [0, 1).
  double drop_tolerance = 1e-10;
  // Use the precomputed range-space fast path when it applies (docs/engine.md;
  // likewise Alternation, alternation.h);
  // false forces the O(p³) null-space method (for comparison and tests).
  bool fast_path = true;
  // OpenMP/BLAS threads for the dense algebra of this step (0 means
  // omp_get_max_threads()). One is faster for small p (docs/performance.md).
  int threads = 1;
  // false: the fast path keeps M_q factored (docs/engine.md, "Factored fast
  // path") when Scalar is double, m + ν ≤ SubspaceSolver::kMaxFactoredRank and it is
  // cheaper: factored_cost_ratio × its sparse products' multiply-adds,
  // p·nnz + 3·min(nnz², nnz·(p + m)) (nnz = nnz(A_r): Y, then A_r·T·A_rᵀ for
  // T = M0, T₂, T₃), at most the explicit form's p²·(m + (m + ν)/2) (Y and
  // the rank-(m + ν) update of M0); otherwise it forms M_b, M_q, M_Y.
  // true: always form them (the explicit path, for comparison and tests).
  bool explicit_operators = false;
  // Cost of one multiply-add in the factored form's sparse loops relative to
  // one in the explicit form's BLAS GEMMs; only the automatic choice uses it
  // (how 5 was chosen: docs/engine.md, the ConstraintOptions table).
  double factored_cost_ratio = 5.0;

  bool is_valid(std::string* why) const;
};

struct ConstraintSummary : Outcome {
  Index m = 0;            // number of constraints
  Index rank = 0;         // numerical rank of Ā = AᵀB·D_s (= rank of A_r)
  double condition = 0.0; // σ_max/σ_min(Ā) over its rank
  bool fast_path = false; // the answer came from the precomputed fast path
  bool factored = false;  // ... with M_q kept factored (no p×p operator formed)
  Index dropped = 0;      // entries of A_r zeroed by drop_tolerance (set_constraints)
  // Set by a caller that knows the full-space problem (the deformer, for a
  // least-squares set): the subspace cannot meet these rows as the full
  // space can (their rank is lower in the subspace, or their condition there
  // is too high for the float basis). More basis directions through the
  // constrained entries (e.g. proxies at the held vertices) make it exact.
  bool beyond_subspace = false;
  double seconds = 0.0;

 protected:
  void add_details(Report* out) const override;
};

}  // namespace qpreduce
