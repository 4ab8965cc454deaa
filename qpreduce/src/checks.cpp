#include "qpreduce/checks.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <utility>

namespace qpreduce {

void check_size(const char* what, Index expected, Index got) {
  if (expected != got) {
    throw std::invalid_argument(fmt::format("{}: expected {}, got {}", what, expected, got));
  }
}

namespace {

// ‖H − Hᵀ‖²_F without forming Hᵀ (a copy of H, 80 MB at n ≈ 10⁵, that
// stayed in the heap under the subspace build's peak): each stored a_ij,
// i ≠ j, is compared with a_ji found by binary search in column i (absent:
// 0). A pair stored both ways is met twice, an entry without its mirror
// once, so the latter counts twice. Needs sorted, compressed columns;
// returns a negative value when they are not.
template <typename Scalar>
double asymmetry_squared(const SparseMatrix<Scalar>& H) {
  if (!H.isCompressed()) return -1.0;
  const int* outer = H.outerIndexPtr();
  const int* inner = H.innerIndexPtr();
  const Scalar* value = H.valuePtr();
  double sum = 0.0;
  for (Index j = 0; j < H.outerSize(); ++j) {
    for (int t = outer[j]; t < outer[j + 1]; ++t) {
      if (t > outer[j] && inner[t] <= inner[t - 1]) return -1.0;  // unsorted or duplicated
      const Index i = inner[t];
      if (i == j) continue;
      const int* first = inner + outer[i];
      const int* last = inner + outer[i + 1];
      const int* hit = std::lower_bound(first, last, static_cast<int>(j));
      const double a = static_cast<double>(value[t]);
      if (hit != last && *hit == j) {
        const double diff = a - static_cast<double>(value[hit - inner]);
        sum += diff * diff;
      } else {
        sum += 2.0 * a * a;
      }
    }
  }
  return sum;
}

}  // namespace

template <typename Scalar>
void check_symmetric(const char* what, const SparseMatrix<Scalar>& H, double tolerance) {
  double asym2 = asymmetry_squared(H);
  if (asym2 < 0.0) {  // unsorted or uncompressed storage: through the transpose
    const SparseMatrix<Scalar> Ht = H.transpose();
    asym2 = static_cast<double>((H - Ht).squaredNorm());
  }
  const double asym = std::sqrt(asym2);
  const double scale = static_cast<double>(H.norm());
  if (!(asym <= tolerance * scale)) {
    throw std::invalid_argument(
        fmt::format("{}: not symmetric (‖H − Hᵀ‖_F = {:.3e} > {:.1e}·‖H‖_F = {:.3e})", what, asym,
                    tolerance, tolerance * scale));
  }
}

template void check_symmetric<double>(const char*, const SparseMatrix<double>&, double);
template void check_symmetric<float>(const char*, const SparseMatrix<float>&, double);

}  // namespace qpreduce
