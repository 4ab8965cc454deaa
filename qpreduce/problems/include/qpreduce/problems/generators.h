// qpreduce — seeded problem generators shared by tests, benchmarks and examples.
//
// Every generator is deterministic for a given seed (std::mt19937_64), so a
// failing test or a benchmark figure can be reproduced exactly.
#pragma once

#include "qpreduce/common.h"

#include <cstdint>
#include <string>
#include <vector>

namespace qpreduce::generators {

// Graph Laplacian of an nx × ny grid (5-point stencil, unit weights) plus
// ridge·I. PSD with a one-dimensional null space (constants) when ridge = 0.
// Size (nx·ny) × (nx·ny); vertex (i, j) has index i + nx·j.
SparseMatrix<double> grid_laplacian_2d(Index nx, Index ny, double ridge = 0.0);

// 7-point Laplacian of an nx × ny × nz grid plus ridge·I; vertex index
// i + nx·(j + ny·k).
SparseMatrix<double> grid_laplacian_3d(Index nx, Index ny, Index nz, double ridge = 0.0);

// Dense random symmetric PSD matrix of size n with a null space of dimension
// `nullity` (H = GᵀG with G (n−nullity)×n Gaussian), stored sparse. Also
// returns an orthonormal basis of its null space (n × nullity) if `null_basis`
// is given.
SparseMatrix<double> random_psd(Index n, Index nullity, std::uint64_t seed,
                                Matrix<double>* null_basis = nullptr);

// Dense random symmetric PSD matrix of size n with a null space of dimension
// `nullity` and a prescribed spectrum: H = V·diag(λ)·Vᵀ with V a random
// orthogonal matrix and the n − nullity positive eigenvalues geometrically
// spaced in [1/condition, 1] (condition ≥ 1). Unlike random_psd (the Gram
// matrix of a nearly square Gaussian, whose condition grows like n²), the
// condition number on the range of H is exactly `condition`. Stored sparse;
// an orthonormal basis of ker H goes to `null_basis` if given.
SparseMatrix<double> random_psd_with_condition(Index n, Index nullity, double condition, std::uint64_t seed,
                                               Matrix<double>* null_basis = nullptr);

// n × d selection matrix: column j has a single 1 at row rows[j].
SparseMatrix<double> selection(Index n, const std::vector<Index>& rows);

// `count` distinct indices from [0, n), sorted, uniformly at random.
std::vector<Index> random_subset(Index n, Index count, std::uint64_t seed);

// n × cols matrix with i.i.d. standard normal entries (dense, stored sparse).
SparseMatrix<double> gaussian_sparse(Index n, Index cols, std::uint64_t seed);

// n × k smooth "trend" basis on an nx × ny grid: products of low-order
// Legendre-like polynomials in x and y (1, x, y, xy, x², y², …), k ≤ 10.
SparseMatrix<double> grid_trend_basis(Index nx, Index ny, Index k);
// Its rows [first, end) alone ((end − first) × k, the same entries).
SparseMatrix<double> grid_trend_basis_rows(Index nx, Index ny, Index k, Index first, Index end);

// Standard normal vector / matrix.
Vector<double> gaussian_vector(Index n, std::uint64_t seed);
Matrix<double> gaussian_matrix(Index rows, Index cols, std::uint64_t seed);

// n × k smooth trend basis on an nx × ny × nz grid: monomials in x, y, z
// (coordinates scaled to [−1, 1]) in graded order 1, x, y, z, xy, xz, yz, x²,
// y², z²; k ≤ 10. Vertex index i + nx·(j + ny·l), as grid_laplacian_3d.
SparseMatrix<double> grid_trend_basis_3d(Index nx, Index ny, Index nz, Index k);

// ---- Theorem 4.10 trials (docs/theorem.md) ---------------------------------
//
// Families of (H, C, D) with demands that leave the design spaces by a
// controlled amount ε:
//     A = C·A_c + ε·E,   q = D·Y + ε·F,
// E (n×m) and F (n) Gaussian, scaled so that ‖E‖_F = ‖C·A_c‖_F and
// ‖F‖ = ‖D·Y‖. For a fixed (family, size, seed) everything but ε is the same,
// so sweeping ε moves one demand along a straight line away from
// Span(C) × Span(D); ε = 0 is a demand the subspace reproduces exactly.
// Eq. 1 has a unique solution iff A has full column rank and
// ker H ∩ ker Aᵀ = {0}; to keep it well conditioned, not just solvable, ν ≤ m
// and A_c (and C, for the dense families) is redrawn deterministically, at
// most 64 times (then std::runtime_error), until C·A_c is
// well conditioned, cond₂(C·A_c) ≤ 100 (the paper's "A is a well-conditioned
// matrix", Section 2), and the ker H part of the constraints is not nearly
// singular: σ_min(Kᵀ·C·A_c) ≥ 0.1·‖C·A_c‖_F/√n and cond₂(Kᵀ·C·A_c) ≤ 10 for
// an orthonormal basis K of ker H.
enum class TheoremFamily {
  DensePsd,     // random_psd_with_condition(n, ν, 1e3), ν ∈ [1, min(m, 3)]; C, D Gaussian
  DensePd,      // random_psd_with_condition(n, 0, 1e3); C, D Gaussian
  Grid2d,       // grid_laplacian_2d, ridge 0 (ker H = constants); C point selections, D trend basis
  Grid2dRidge,  // as Grid2d with ridge 0.1 (PD, condition ≈ 81)
  Grid3d,       // grid_laplacian_3d, ridge 0; C point selections, D 3-D trend basis
  Grid3dRidge,  // as Grid3d with ridge 0.1 (PD, condition ≈ 121)
};

const char* to_string(TheoremFamily family);  // "dense-psd", "grid2d-ridge", …
// Every family, in declaration order.
std::vector<TheoremFamily> theorem_families();
// Inverse of to_string. Throws std::invalid_argument naming the valid choices.
TheoremFamily parse_theorem_family(const std::string& name);

// One seeded problem of Eq. 1 with its design spaces (Eq. 2).
struct TheoremTrial {
  TheoremFamily family = TheoremFamily::DensePsd;
  Index size = 0;             // requested size (n is the nearest grid size)
  double epsilon = 0.0;       // distance of the demand from the design spaces
  std::uint64_t seed = 0;
  SparseMatrix<double> H;     // n × n, symmetric PSD
  SparseMatrix<double> C;     // n × d, d ∈ [4, 12]
  SparseMatrix<double> D;     // n × k, k ∈ [1, 6]
  Matrix<double> A_c;         // d × m, m ∈ [1, min(d, 6)], Gaussian
  Vector<double> Y;           // k, Gaussian
  Matrix<double> E;           // n × m, Gaussian, ‖E‖_F = ‖C·A_c‖_F
  Vector<double> F;           // n, Gaussian, ‖F‖ = ‖D·Y‖
  SparseMatrix<double> A;     // n × m, C·A_c + ε·E
  Vector<double> b;           // m, Gaussian
  Vector<double> q;           // n, D·Y + ε·F
  Matrix<double> kernel;      // n × ν, orthonormal basis of ker H (ν = 0 when PD)

  Index n() const { return H.rows(); }
  Index d() const { return C.cols(); }
  Index k() const { return D.cols(); }
  Index m() const { return A.cols(); }
  // Re-forms A and q for another ε (everything else unchanged). Throws
  // std::invalid_argument when ε is negative or not finite.
  void set_epsilon(double epsilon);
};

// Deterministic in (family, size, seed); ε only scales E and F. Dense
// families have n = size; grids have n = s² (s = round(√size)) or s³
// (s = round(∛size)). Throws std::invalid_argument when size < 24 or ε is
// negative or not finite.
TheoremTrial theorem_problem(TheoremFamily family, Index size, double epsilon, std::uint64_t seed);

}  // namespace qpreduce::generators
