// qpreduce — seeded problem generators shared by tests, benchmarks and examples.
//
// Every generator is deterministic for a given seed (std::mt19937_64), so a
// failing test or a benchmark figure can be reproduced exactly.
#pragma once

#include "qpreduce/common.h"

#include <cstdint>
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

// n × d selection matrix: column j has a single 1 at row rows[j].
SparseMatrix<double> selection(Index n, const std::vector<Index>& rows);

// `count` distinct indices from [0, n), sorted, uniformly at random.
std::vector<Index> random_subset(Index n, Index count, std::uint64_t seed);

// n × cols matrix with i.i.d. standard normal entries (dense, stored sparse).
SparseMatrix<double> gaussian_sparse(Index n, Index cols, std::uint64_t seed);

// n × k smooth "trend" basis on an nx × ny grid: products of low-order
// Legendre-like polynomials in x and y (1, x, y, xy, x², y², …), k ≤ 10.
SparseMatrix<double> grid_trend_basis(Index nx, Index ny, Index k);

// Standard normal vector / matrix.
Vector<double> gaussian_vector(Index n, std::uint64_t seed);
Matrix<double> gaussian_matrix(Index rows, Index cols, std::uint64_t seed);

}  // namespace qpreduce::generators
