// qpreduce — argument checks, for the engine and for the plugins built on it.
//
// The checks are the API-boundary layer of qpreduce's errors (see common.h):
// each throws std::invalid_argument with a message that starts with `what`.
#pragma once

#include "qpreduce/common.h"

#include <stdexcept>
#include <string>

namespace qpreduce {

// Throws std::invalid_argument("<what>: expected <expected>, got <got>") when
// expected != got.
void check_size(const char* what, Index expected, Index got);

// Throws std::invalid_argument("<what>: contains NaN or infinite entries")
// when any (stored) entry of m is NaN or infinite.
template <typename Derived>
void check_finite(const char* what, const Eigen::MatrixBase<Derived>& m) {
  if (!m.allFinite()) {
    throw std::invalid_argument(std::string(what) + ": contains NaN or infinite entries");
  }
}
template <typename Scalar>
void check_finite(const char* what, const SparseMatrix<Scalar>& m) {
  const Eigen::Map<const Vector<Scalar>> values(m.valuePtr(), m.nonZeros());
  if (!values.allFinite()) {
    throw std::invalid_argument(std::string(what) + ": contains NaN or infinite entries");
  }
}

// Throws std::invalid_argument when ‖H − Hᵀ‖_F > tolerance·‖H‖_F.
// H: n by n.
template <typename Scalar>
void check_symmetric(const char* what, const SparseMatrix<Scalar>& H, double tolerance);

}  // namespace qpreduce
