// ‖A − B‖_F / ‖B‖_F of two dense matrices, for the distributed tests.
#pragma once

#include <qpreduce/common.h>

#include <algorithm>

namespace qpreduce::testing_distributed {

inline double relative_difference(const Matrix<double>& A, const Matrix<double>& B) {
  return (A - B).norm() / std::max(B.norm(), 1e-300);
}

}  // namespace qpreduce::testing_distributed
