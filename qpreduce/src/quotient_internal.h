// Dense helpers shared by the quotient analysis (quotient.cpp) and the
// Theorem 4.10 checker (theorem.cpp).
#pragma once

#include "qpreduce/quotient.h"

#include "subspace_internal.h"

#include <Eigen/Dense>

#include <limits>
#include <stdexcept>
#include <string>

namespace qpreduce::detail {

using MatD = Matrix<double>;
using VecD = Vector<double>;
constexpr double kInf = std::numeric_limits<double>::infinity();

// Thin SVD truncated at tolerance·σ_max: M = U·diag(σ)·Vᵀ with `rank` columns.
struct TruncatedSvd {
  MatD U;          // rows × rank
  VecD sigma;      // rank
  MatD V;          // cols × rank
  Index rank = 0;
  double sigma_max = 0.0;
  double sigma_min = 0.0;  // smallest of min(rows, cols) singular values (0 if cols > rows)
};

inline TruncatedSvd truncated_svd(const MatD& M, double tolerance, double reference = -1.0) {
  TruncatedSvd s;
  if (M.rows() == 0 || M.cols() == 0) {
    s.U.resize(M.rows(), 0);
    s.V.resize(M.cols(), 0);
    return s;
  }
  Eigen::JacobiSVD<MatD> svd(M, Eigen::ComputeThinU | Eigen::ComputeThinV);
  const VecD& sv = svd.singularValues();
  s.sigma_max = sv(0);
  s.sigma_min = M.cols() > M.rows() ? 0.0 : sv(sv.size() - 1);
  // Rank relative to `reference` when given (e.g. σ_max(Â) for Â_p = ÎÂ).
  const double threshold = tolerance * (reference >= 0.0 ? reference : s.sigma_max);
  while (s.rank < sv.size() && sv(s.rank) > threshold) ++s.rank;
  s.U = svd.matrixU().leftCols(s.rank);
  s.V = svd.matrixV().leftCols(s.rank);
  s.sigma = sv.head(s.rank);
  return s;
}

inline double spectral_norm(const MatD& M) {
  if (M.size() == 0) return 0.0;
  return Eigen::JacobiSVD<MatD>(M).singularValues()(0);
}

inline void require_options(const QuotientOptions& options) {
  std::string why;
  if (!options.is_valid(&why)) throw std::invalid_argument("QuotientOptions: " + why);
}

// Sets this thread's OpenMP team size (read by Eigen's products and by the
// engine) for the scope; 0 leaves it unchanged.
using ScopedThreads = ScopedOmpThreads;

}  // namespace qpreduce::detail
