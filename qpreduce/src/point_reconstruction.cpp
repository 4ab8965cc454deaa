#include "qpreduce/checks.h"
#include "qpreduce/point_reconstruction.h"

#include "simd_kernels.h"

#include <fmt/format.h>

#include <cmath>
#include <stdexcept>

namespace qpreduce {

namespace {

// Below this many entries of B (256 KiB of floats) one thread finishes
// before a team would be woken.
constexpr Index kParallelEntries = Index(1) << 16;
// Bases up to this size are read in the interleaved order, larger ones in
// the sequential order (simd_kernels.h, rows3_dot_avx2): the L3 cache of the
// machine we measured on (lscpu; glibc's sysconf reported the host's 256 MiB
// there, so it is not asked). Between 30 and 40 MiB the two orders measured
// the same.
constexpr Index kInterleavedMaxBytes = Index(32) << 20;
// How far ahead (bytes) the interleaved order prefetches each row.
constexpr Index kPrefetchBytes = 4096;

template <typename Basis, typename Vector, typename Rotation>
void check_arguments(const Basis& B, const Vector& w, const Rotation& R, double scale, const Eigen::Vector3d& offset) {
  if (B.rows() % 3 != 0)
    throw std::invalid_argument(
        fmt::format("reconstruct_points: B has {} rows, expected a multiple of 3 (x, y, z per point)", B.rows()));
  check_size("reconstruct_points: w size (B's columns)", B.cols(), w.size());
  check_finite("reconstruct_points: w", w);
  check_finite("reconstruct_points: R", R);
  if (!std::isfinite(scale)) throw std::invalid_argument(fmt::format("reconstruct_points: scale is {}", scale));
  check_finite("reconstruct_points: offset", offset);
}

template <typename Basis, typename Vector, typename Rotation>
void reconstruct_into(const Basis& B, const Vector& w, const Rotation& R, Points3d* X_out, double scale,
                      const Eigen::Vector3d& offset) {
  if (X_out == nullptr) throw std::invalid_argument("reconstruct_points: X_out is null");
  check_arguments(B, w, R, scale, offset);
  if (X_out->rows() != B.rows() / 3) X_out->resize(B.rows() / 3, 3);
  reconstruct_points(B, w, R, Eigen::Map<Points3d>(X_out->data(), X_out->rows(), 3), scale, offset);
}

}  // namespace

void reconstruct_points(const RowMatrixXf& B, const Eigen::VectorXf& w, const Eigen::Matrix3f& R, Points3d* X_out,
                        double scale, const Eigen::Vector3d& offset) {
  reconstruct_into(B, w, R, X_out, scale, offset);
}

void reconstruct_points(const RowMatrixXd& B, const Eigen::VectorXd& w, const Eigen::Matrix3d& R, Points3d* X_out,
                        double scale, const Eigen::Vector3d& offset) {
  reconstruct_into(B, w, R, X_out, scale, offset);
}

void reconstruct_points(const RowMatrixXf& B, const Eigen::VectorXf& w, const Eigen::Matrix3f& R,
                        Eigen::Map<Points3d> X_out, double scale, const Eigen::Vector3d& offset) {
  check_arguments(B, w, R, scale, offset);
  const Index n = B.rows() / 3, p = B.cols();
  check_size("reconstruct_points: X_out rows (B's rows / 3)", n, X_out.rows());
  const float* base = B.data();
  const float* wp = w.data();
  double* out = X_out.data();
  [[maybe_unused]] const detail::RowOrder order = B.size() * Index(sizeof(float)) <= kInterleavedMaxBytes
                                     ? detail::RowOrder::Interleaved
                                     : detail::RowOrder::Sequential;
  // The kernel is chosen once per call, not per point.
  auto run = [&](auto&& rows3_dot) {
#pragma omp parallel for schedule(static) if (B.size() > kParallelEntries)
    for (Index v = 0; v < n; ++v) {
      Eigen::Vector3f q;
      rows3_dot(base + 3 * v * p, q.data());
      Eigen::Map<Eigen::RowVector3d>(out + 3 * v) = (scale * (R * q).cast<double>() + offset).transpose();
    }
  };
#ifdef QPREDUCE_HAVE_AVX2_KERNELS
  if (detail::cpu_has_avx2_fma()) {
    run([&](const float* rows, float* q) { detail::rows3_dot_avx2(rows, p, wp, q, order, kPrefetchBytes); });
    return;
  }
#endif
  run([&](const float* rows, float* q) { detail::rows3_dot_eigen(rows, p, wp, q); });
}

void reconstruct_points(const RowMatrixXd& B, const Eigen::VectorXd& w, const Eigen::Matrix3d& R,
                        Eigen::Map<Points3d> X_out, double scale, const Eigen::Vector3d& offset) {
  check_arguments(B, w, R, scale, offset);
  const Index n = B.rows() / 3, p = B.cols();
  check_size("reconstruct_points: X_out rows (B's rows / 3)", n, X_out.rows());
  using Rows3 = Eigen::Map<const Eigen::Matrix<double, 3, Eigen::Dynamic, Eigen::RowMajor>>;
#pragma omp parallel for schedule(static) if (B.size() > kParallelEntries / 2)
  for (Index v = 0; v < n; ++v) {
    const Eigen::Vector3d q = Rows3(B.data() + 3 * v * p, 3, p) * w;
    X_out.row(v) = (scale * (R * q) + offset).transpose();
  }
}

}  // namespace qpreduce
