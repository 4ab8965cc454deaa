// Private to the deformer: the control system that Deformer::precompute
// assembles (precompute.cpp) and the rows of it one process assembles in a
// distributed precompute (precompute_part.cpp).
#pragma once

#include "qpreduce/deform/deformer/deformer.h"

#include "state.h"

#include <vector>

namespace qpreduce::deform::detail {

using Groups = std::vector<std::vector<Index>>;

// In a process's part (Deformer::precompute_part) Hu, Du and DV hold only
// its control rows [first, first + count): Hu count × n_u, Du count × 9d,
// DV the rows of PᵀD_V (count × 9d, the paper's Phase 2 only).
struct ControlSystem {
  SparseMatrix<double> Hu;  // n_u × n_u
  SparseMatrix<double> Du;  // n_u × 9d
  SparseMatrix<double> DV;  // 3n × 9d
  SparseMatrix<double> K;   // 9d × 9d, or empty when Q is kept in u
  SparseMatrix<double> P;   // 3n × n_u
};

// Control rows [first, end) of one process: the block partition of
// qpreduce::distributed::owned_rows.
struct ControlRows {
  Index first = 0, end = 0;
  Index count() const { return end - first; }
};
inline ControlRows control_rows(Index nu, Deformer::Partition part) {
  return {nu * part.process / part.processes, nu * (part.process + 1) / part.processes};
}

// (Eigen 3.4's SparseMatrix has no move operations and keeps its storage on
// assignment from an empty matrix: swap with an empty one frees it.)
inline void free_sparse(SparseMatrix<double>* A) { SparseMatrix<double>().swap(*A); }

// The whole control system, then this process's rows: one process (K = 1)
// holds the whole system anyway.
ControlSystem whole_then_rows(Model& model, const DeformableMesh& mesh, Deformer::Partition part,
                              ClusterRotationFit fit);

// Whether the model's L_QQ is block diagonal, from one element's assembly.
bool q_separable(const Model& model, const DeformableMesh& mesh);

// This process's rows of the control system (Q eliminated), assembled on
// its owned and ghost elements; *assembled counts them.
ControlSystem control_system_rows(const Model& model, const DeformableMesh& mesh, ControlRows rows,
                                  Deformer::Partition part, ClusterRotationFit fit,
                                  const Deformer::SumOverProcesses& sum, Index* assembled);

// ---- γ > 0: Q kept in u = [control (patch_base + 12s); Q (4r)] ----
//
// The moving-frame term (Eq. 11) couples neighbouring elements' Q, so the
// blocks are no longer sums over elements alone; a process's rows are still
// complete on a subset of them:
//   a free vertex's rows    every element with that vertex (owned + ghosts);
//   element k's rows of Q   k and its neighbours (element_neighbours), whose
//                           pairs select_elements keeps;
// all assembled in one piece. The patch unknowns' rows are summed over the
// processes from each one's owned elements with a patch vertex (the pairs
// reach no patch row). K is empty: Q is not eliminated.
ControlSystem kept_q_control_rows(Model& model, const DeformableMesh& mesh, Deformer::Partition part,
                                  ClusterRotationFit fit, const Deformer::SumOverProcesses& sum, Index* assembled);

// Q kept: u = [control (patch_base + 12s); Q (4r)]. The model's blocks on
// the elements `which` (ascending; null: all of them, in order) in the
// control layer: H_u = P̂ᵀ·L·P̂ (symmetrised), D_u = P̂ᵀ·D (n_u × 9d) and
// D_V = D's vertex rows (3n × 9d), where P̂ ((3n + 4|which|) × n_u) is
// blockdiag(P, I): the subset's [V′; Q] from u. P: control_matrix().
ControlSystem kept_q_blocks(const Model& model, const ModifiedArapSystem& sys, const SparseMatrix<double>& P,
                            const std::vector<Index>* which);

// The model's energy (Q eliminated when L_QQ is block diagonal), then the
// control layer. The full system is freed before the factorization.
ControlSystem assemble_control_system(Model& model, const DeformableMesh& mesh);

}  // namespace qpreduce::deform::detail
