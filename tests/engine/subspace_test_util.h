// Helpers shared by the subspace, reduced-solve and constraint tests: a
// seeded demand inside the design spaces, and a dense KKT solve of Eq. 1 as
// the independent truth for small problems.
#pragma once

#include "qpreduce/problems/generators.h"
#include "qpreduce/subspace_solver.h"

#include <Eigen/Dense>

#include <cstdint>

namespace subspace_test {

using qpreduce::Index;
using qpreduce::Matrix;
using qpreduce::SparseMatrix;
using qpreduce::Vector;
namespace gen = qpreduce::generators;

// A demand that lies in the design spaces: A = C·A_c, q = D·Y.
struct Problem {
  SparseMatrix<double> H, C, D, A;
  Vector<double> b, q, Y;
};

// H: the (nx·ny) grid Laplacian plus `ridge`·I; C: 12 selected vertices;
// D: 4 trend functions; A_c: 12 × 5, Y and b Gaussian (all from `seed`).
inline Problem in_span_problem(Index nx, Index ny, double ridge, std::uint64_t seed) {
  Problem p;
  const Index n = nx * ny;
  p.H = gen::grid_laplacian_2d(nx, ny, ridge);
  p.C = gen::selection(n, gen::random_subset(n, 12, seed));
  p.D = gen::grid_trend_basis(nx, ny, 4);
  const Matrix<double> Ac = gen::gaussian_matrix(12, 5, seed + 1);
  p.A = (p.C * Ac).sparseView();
  p.Y = gen::gaussian_vector(4, seed + 2);
  p.q = p.D * p.Y;
  p.b = gen::gaussian_vector(5, seed + 3);
  return p;
}

// Dense KKT solve of Eq. 1, the independent truth for small problems.
inline Vector<double> dense_kkt_solve(const SparseMatrix<double>& H, const SparseMatrix<double>& A,
                                      const Vector<double>& b, const Vector<double>& q) {
  const Index n = H.rows(), m = A.cols();
  Matrix<double> K = Matrix<double>::Zero(n + m, n + m);
  K.topLeftCorner(n, n) = Matrix<double>(H);
  K.topRightCorner(n, m) = Matrix<double>(A);
  K.bottomLeftCorner(m, n) = Matrix<double>(A).transpose();
  Vector<double> rhs(n + m);
  rhs << q, b;
  return K.fullPivLu().solve(rhs).head(n);
}

}  // namespace subspace_test
