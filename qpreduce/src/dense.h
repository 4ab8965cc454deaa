// Small dense helpers shared by the engine's translation units.
#pragma once

#include "qpreduce/common.h"

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <limits>
#include <vector>

// LAPACK's symmetric divide-and-conquer eigensolver (the LAPACK CHOLMOD links).
extern "C" void dsyevd_(const char* jobz, const char* uplo, const int* n, double* a, const int* lda, double* w,
                        double* work, const int* lwork, int* iwork, const int* liwork, int* info);

namespace qpreduce::detail {

// Rows from which symmetric_eigen calls LAPACK: below it, Eigen's solver
// (the small operators of the usual proxy counts stay as they were).
inline constexpr Index kLapackEigenRows = 400;

// Eigenvalues of the symmetric S (its lower triangle is read), ascending,
// into *values, and with `vectors` the orthonormal eigenvectors as its
// columns. From kLapackEigenRows rows LAPACK's divide-and-conquer dsyevd
// (blocked, through the system BLAS), else Eigen's SelfAdjointEigenSolver.
// False when the solver does not converge (*values then unspecified).
inline bool symmetric_eigen(Matrix<double> S, Eigen::VectorXd* values, Matrix<double>* vectors = nullptr) {
  const Index n = S.rows();
  if (n < kLapackEigenRows) {
    Eigen::SelfAdjointEigenSolver<Matrix<double>> es(S, vectors ? Eigen::ComputeEigenvectors : Eigen::EigenvaluesOnly);
    if (es.info() != Eigen::Success) return false;
    *values = es.eigenvalues();
    if (vectors) *vectors = es.eigenvectors();
    return true;
  }
  Matrix<double>& A = S;  // taken by value: LAPACK overwrites it with the eigenvectors
  values->resize(n);
  const char jobz = vectors ? 'V' : 'N', uplo = 'L';
  const int m = static_cast<int>(n), lda = m;
  int info = 0, lwork = -1, liwork = -1, iwork_size = 0;
  double work_size = 0.0;
  dsyevd_(&jobz, &uplo, &m, A.data(), &lda, values->data(), &work_size, &lwork, &iwork_size, &liwork, &info);
  if (info != 0) return false;
  lwork = static_cast<int>(work_size);
  liwork = iwork_size;
  std::vector<double> work(static_cast<size_t>(std::max(lwork, 1)));
  std::vector<int> iwork(static_cast<size_t>(std::max(liwork, 1)));
  dsyevd_(&jobz, &uplo, &m, A.data(), &lda, values->data(), work.data(), &lwork, iwork.data(), &liwork, &info);
  if (info != 0) return false;
  if (vectors) *vectors = std::move(A);
  return true;
}

// Eigenvalues of a symmetric matrix, ascending (NaN entries when the solver
// does not converge, which every comparison then refuses).
inline Eigen::VectorXd symmetric_eigenvalues(const Matrix<double>& S) {
  if (S.rows() == 0) return Eigen::VectorXd();
  Eigen::VectorXd values;
  if (!symmetric_eigen(S, &values)) values.setConstant(S.rows(), std::numeric_limits<double>::quiet_NaN());
  return values;
}

// Number of eigenvalues above tolerance·max|λ| (0 for an all-zero matrix).
inline Index numerical_rank(const Eigen::VectorXd& eigenvalues, double tolerance) {
  if (eigenvalues.size() == 0) return 0;
  const double top = eigenvalues.cwiseAbs().maxCoeff();
  if (top <= 0.0) return 0;
  return (eigenvalues.array() > tolerance * top).count();
}

}  // namespace qpreduce::detail
