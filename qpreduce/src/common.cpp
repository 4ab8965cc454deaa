#include "qpreduce/common.h"

#include <fmt/format.h>

namespace qpreduce {

const char* to_string(Status status) {
  switch (status) {
    case Status::NotRun: return "not-run";
    case Status::Success: return "success";
    case Status::ConstraintsLeastSquares: return "constraints-least-squares";
    case Status::RankDeficientC: return "rank-deficient-C";
    case Status::DependentCD: return "dependent-C-D";
    case Status::IndefiniteH: return "indefinite-H";
    case Status::SingularKKT: return "singular-KKT";
    case Status::Unbounded: return "unbounded";
    case Status::NumericalFailure: return "numerical-failure";
  }
  return "unknown";
}

namespace detail {

void check_size(const char* what, Index expected, Index got) {
  if (expected != got) {
    throw std::invalid_argument(fmt::format("{}: expected {}, got {}", what, expected, got));
  }
}

template <typename Scalar>
void check_symmetric(const char* what, const SparseMatrix<Scalar>& H, double tolerance) {
  const SparseMatrix<Scalar> Ht = H.transpose();
  const double asym = static_cast<double>((H - Ht).norm());
  const double scale = static_cast<double>(H.norm());
  if (asym > tolerance * scale) {
    throw std::invalid_argument(
        fmt::format("{}: not symmetric (‖H − Hᵀ‖_F = {:.3e} > {:.1e}·‖H‖_F = {:.3e})", what, asym,
                    tolerance, tolerance * scale));
  }
}

template void check_symmetric<double>(const char*, const SparseMatrix<double>&, double);
template void check_symmetric<float>(const char*, const SparseMatrix<float>&, double);

}  // namespace detail
}  // namespace qpreduce
