// Small dense helpers shared by the engine's translation units.
#pragma once

#include "qpreduce/common.h"

#include <Eigen/Eigenvalues>

namespace qpreduce::detail {

// Eigenvalues of a symmetric matrix, ascending.
inline Eigen::VectorXd symmetric_eigenvalues(const Matrix<double>& S) {
  if (S.rows() == 0) return Eigen::VectorXd();
  Eigen::SelfAdjointEigenSolver<Matrix<double>> es(S, Eigen::EigenvaluesOnly);
  return es.eigenvalues();
}

// Number of eigenvalues above tolerance·max|λ| (0 for an all-zero matrix).
inline Index numerical_rank(const Eigen::VectorXd& eigenvalues, double tolerance) {
  if (eigenvalues.size() == 0) return 0;
  const double top = eigenvalues.cwiseAbs().maxCoeff();
  if (top <= 0.0) return 0;
  return (eigenvalues.array() > tolerance * top).count();
}

}  // namespace qpreduce::detail
