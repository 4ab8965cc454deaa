// qpreduce — the variational subspace (Eq. 4–5) built on MUMPS over MPI.
//
// The same build as build_subspace (subspace.h), for problems whose n × p
// basis B = [N UD] (p = d + k) does not fit on one machine. Under
// `mpirun -np K` every rank of `comm` calls build_subspace_mumps together
// (a collective call) and owns a contiguous block of rows, owned_rows(n):
//
//   * assembly — each rank hands MUMPS only its own rows of the factored
//     matrix as distributed COO (ICNTL(18) = 3): rows of
//       H_ρ = H + ρ·CpCpᵀ  (n × n, SPD; the augmented route, SYM = 1),
//       H               (augment = false; SYM = 1), or
//       K = [[H, C], [Cᵀ, 0]]  ((n+d) × (n+d), symmetric indefinite; the
//       KKT route, SYM = 2; the last rank also holds K's d rows of Cᵀ);
//   * analysis and factorization — MUMPS, in parallel over the ranks; the
//     ordering is PT-Scotch in parallel (ICNTL(28) = 2, ICNTL(29) = 1) when
//     the MUMPS build has it and K > 1, else MUMPS's automatic choice on the
//     host; DistributedSummary::ordering says which was used;
//   * the p solves — in blocks of SubspaceOptions::block_size columns with a
//     centralized right-hand side and solution: rank 0 holds one n × b block
//     at a time and scatters its rows, column by column, to their owners (MUMPS's own
//     distributed solution, ICNTL(21) = 1, comes back in MUMPS's row mapping
//     and would need the same all-to-all);
//   * the dense algebra — S = CᵀG (d × d), CᵀF (d × k), Dᵀ·UD (k × k),
//     H_r = BᵀHB (p × p) and BᵀD (p × k) are per-rank partial sums over owned
//     rows, reduced with MPI_Allreduce; N = G·S⁻¹ and UD = F − N·CᵀF are then
//     formed by row blocks in place. H·B is computed by column blocks of B
//     gathered to every rank (n × MumpsOptions::gather_columns at a time).
//     No rank holds the whole n × p basis.
//
// Math and statuses as in subspace.h: with G = H_ρ⁻¹C, F = H_ρ⁻¹D, S = CᵀG,
//     N = G·S⁻¹,  UD = F − G·S⁻¹·(CᵀF);
// on the KKT route [N UD] is the top n rows of K⁻¹·[[0, D], [I, 0]].
// A failed factorization (MUMPS INFOG(1) < 0, negative pivots of an SPD
// route, a failed known-answer solve) comes back with the same Status and
// message on every rank: MUMPS's INFOG is global, and every other decision is
// taken on reduced numbers.
#pragma once

#include "qpreduce/subspace.h"

#include <mpi.h>

#include <functional>

#include <string>
#include <vector>

namespace qpreduce::distributed {

// Rows [begin, end) of an n-row matrix owned by one rank.
struct RowRange {
  Index begin = 0, end = 0;
  Index size() const { return end - begin; }
};

// The contiguous block partition: rank r of K owns [⌊r·n/K⌋, ⌊(r+1)·n/K⌋).
RowRange owned_rows(Index n, int rank, int ranks);
// This rank's block of n rows in `comm`.
RowRange owned_rows(Index n, MPI_Comm comm);

struct MumpsOptions {
  // Parallel ordering (PT-Scotch, ICNTL(28) = 2) when K > 1 and the MUMPS
  // build has it; false, or otherwise: MUMPS's automatic sequential choice.
  bool parallel_ordering = true;
  // Percent added to MUMPS's estimated working space (ICNTL(14); MUMPS's
  // default is 20). A too-small estimate gives INFOG(1) = −9, reported.
  int workspace_percent = 40;
  // Columns of B = [N UD] gathered whole to every rank at once for H·B (the
  // H_r and residual pass): n × gather_columns doubles per rank. Fewer
  // columns, less memory, more (narrower) sparse products.
  Index gather_columns = 16;
  // Empty: the factor stays in memory. A directory: MUMPS's out-of-core
  // factorization (ICNTL(22) = 1) writes the factor there (OOC_TMPDIR; one
  // set of files per rank, deleted when the build ends) and reads it back
  // for the solves, so a rank holds only the active fronts: less memory per
  // rank, somewhat slower solves (measured in docs/scaling.md). It must exist on
  // every rank (a local disk per node; at most 255 characters); a rank that
  // cannot write there fails the build with MUMPS's status and message.
  std::string out_of_core_directory;
  bool is_valid(std::string* why) const;
};

// backend_used stays Backend::Auto (the Backend enum names the single-process
// backends); kkt_route says which matrix MUMPS factored.
struct DistributedSummary : SubspaceSummary {
  int ranks = 0;
  bool kkt_route = false;        // K = [[H, C], [Cᵀ, 0]] (else H_ρ, or H without augmentation)
  std::string ordering;          // e.g. "PT-Scotch (parallel)", "METIS (sequential)"
  int mumps_infog1 = 0;          // INFOG(1), INFOG(2) of the last MUMPS call (< 0: its error)
  int mumps_infog2 = 0;
  double factor_megabytes_max = 0.0;    // INFOG(21): largest MUMPS memory of one rank, MB
  double factor_megabytes_total = 0.0;  // INFOG(22): summed over the ranks, MB
  double reduce_seconds = 0.0;          // the reduced operators and the residual

 protected:
  void add_details(Report* out) const override;
};

// This rank's part of the subspace, and the reduced operators every rank holds.
struct DistributedSubspace {
  Index n = 0, d = 0, k = 0;
  RowRange rows;           // owned_rows(n, comm)
  Matrix<double> N_rows;   // rows.size() × d: rows [begin, end) of N
  Matrix<double> UD_rows;  // rows.size() × k: rows [begin, end) of UD
  Matrix<double> Hr;       // p × p, H_r = BᵀHB (as SubspaceSolver makes it)
  Matrix<double> BtD;      // p × k, BᵀD
};

// Collective over `comm`. H_rows: rows owned_rows(n, comm) of the symmetric
// PSD H (rows.size() × n; its symmetry is the caller's promise, only these
// rows are seen); C (n × d) and D (n × k) whole on every rank (thin and
// sparse; only this rank's rows of D are used: build_subspace_mumps_rows
// takes just those). Options as for build_subspace; backend SparseLU selects the KKT
// route, Auto chooses it on the same fill test, Cholmod/SimplicialLDLT the
// augmented (or, augment = false, plain) SPD route. ordering_groups is ignored
// (MUMPS orders the unknowns).
// Throws std::invalid_argument (on every rank: the checks are agreed) on bad
// sizes, NaN/Inf, invalid options; numerical failures come back as a status
// with a message and `out` empty.
DistributedSummary build_subspace_mumps(MPI_Comm comm, const SparseMatrix<double>& H_rows,
                                        const SparseMatrix<double>& C, const SparseMatrix<double>& D,
                                        const SubspaceOptions& options, const MumpsOptions& mumps,
                                        DistributedSubspace* out);

// The same with D by rows too: D_rows holds rows owned_rows(n, comm) of D
// (rows.size() × k), so that no rank holds the whole D either. Rank 0
// gathers D's columns one at a time into its n × block_size right-hand side.
DistributedSummary build_subspace_mumps_rows(MPI_Comm comm, const SparseMatrix<double>& H_rows,
                                             const SparseMatrix<double>& C, const SparseMatrix<double>& D_rows,
                                             const SubspaceOptions& options, const MumpsOptions& mumps,
                                             DistributedSubspace* out);

// Collective: the whole N (n × d) and UD (n × k) on `root`, gathered one
// column at a time straight into place; other ranks' `whole` is left empty.
// For writers of the single-machine model cache, whose format holds the
// double basis: root then holds n × p doubles, the other ranks none.
void gather_subspace(MPI_Comm comm, const DistributedSubspace& part, int root, VariationalSubspace<double>* whole);

// The on-site products of a demand over the ranks' rows of B = [N UD]
// (each rank passes the same whole inputs; every one is collective):
//   reduced_constraints  A_r = AᵀB (m × p), summed over the ranks, on every
//                        rank; A: n × m.
//   reduced_linear_term  q_r = Bᵀq (p), summed, on every rank; q: n.
//   gather_solution      X = N·z + UD·y (n) for w = [z; y] (p), each rank its
//                        rows, gathered on `root` (other ranks' *X untouched).
// Throws std::invalid_argument on sizes that do not match the subspace.
Matrix<double> reduced_constraints(MPI_Comm comm, const DistributedSubspace& part, const SparseMatrix<double>& A);
Vector<double> reduced_linear_term(MPI_Comm comm, const DistributedSubspace& part, const Vector<double>& q);
void gather_solution(MPI_Comm comm, const DistributedSubspace& part, const Vector<double>& w, int root,
                     Vector<double>* X);

// Small collectives for the callers of the above (every one collective):
//   sum_over_ranks  M's entries summed over the ranks of `comm`, in place, on
//                   every rank (the same shape everywhere; empty: nothing).
//   gather_values   every rank's `mine` (the same length on every rank),
//                   rank after rank, on `root` (size × mine.size()); empty
//                   elsewhere.
void sum_over_ranks(MPI_Comm comm, Matrix<double>* M);
std::vector<double> gather_values(MPI_Comm comm, const std::vector<double>& mine, int root);

// A row-distributed float matrix (`cols` columns; each rank owns the rows
// `mine`, contiguous, the ranks' blocks in rank order) streamed to `root`
// chunk by chunk (at most chunk_rows rows at a time), so that no rank ever
// holds it whole: `make(first, count, &rows)` writes rows [first, first +
// count) of this rank's block (count × cols), as each chunk is needed.
//   On root: returns `next`; each call writes the next chunk's first row and
//   rows, rank 0's block first and the last rank's last (root's own made in
//   place, the others' received), and returns false when all are done. Call
//   it until it returns false: the other ranks wait in it.
//   Elsewhere: sends this rank's rows and returns an empty function.
// Collective. Throws std::invalid_argument on cols < 1, chunk_rows < 1, or a
// root outside comm.
using FloatRows = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
using MakeRows = std::function<void(Index first, Index count, FloatRows* rows)>;
using NextRows = std::function<bool(Index* first, FloatRows* rows)>;
NextRows stream_rows_to_root(MPI_Comm comm, int root, RowRange mine, Index cols, const MakeRows& make,
                             Index chunk_rows = 4096);

// build_subspace_mumps for a caller that holds the whole H on every rank
// (each rank passes its own rows), then gather_subspace to `root`: there B is
// the whole subspace; H_r and BᵀD are on every rank, B is empty elsewhere.
// What SubspaceSolver::restore needs, for the single-machine tools.
DistributedSummary build_subspace_mumps_on_root(MPI_Comm comm, const SparseMatrix<double>& H,
                                                const SparseMatrix<double>& C, const SparseMatrix<double>& D,
                                                const SubspaceOptions& options, const MumpsOptions& mumps, int root,
                                                VariationalSubspace<double>* B, Matrix<double>* Hr,
                                                Matrix<double>* BtD);

}  // namespace qpreduce::distributed
