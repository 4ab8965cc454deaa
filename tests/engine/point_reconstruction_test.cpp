// reconstruct_points (qpreduce/point_reconstruction.h) and, white-box, its
// per-point kernels (qpreduce/src/simd_kernels.h): both AVX2 + FMA orders and
// the Eigen fallback, each called directly, against a double reference.
#include <catch2/catch.hpp>

#include "simd_kernels.h"

#include <qpreduce/point_reconstruction.h>

#include <Eigen/Geometry>
#include <omp.h>

#include <cmath>
#include <limits>
#include <random>
#include <string>
#include <vector>

using namespace qpreduce;

namespace {

// |float result − exact| ≤ p·2⁻²³·Σ|b_j·w_j| (a loose form of the
// recursive-summation bound, pairwise lanes included) plus underflow slack.
double float_dot_bound(const float* b, const float* w, Index p) {
  double s = 0.0;
  for (Index j = 0; j < p; ++j) s += std::abs(double(b[j]) * double(w[j]));
  return (double(p) + 8.0) * std::ldexp(1.0, -23) * s + 1e-30;
}

double exact_dot(const float* b, const float* w, Index p) {
  double s = 0.0;
  for (Index j = 0; j < p; ++j) s += double(b[j]) * double(w[j]);
  return s;
}

RowMatrixXf random_rows(Index rows, Index cols, std::mt19937& gen) {
  std::normal_distribution<float> value;
  RowMatrixXf B(rows, cols);
  for (Index i = 0; i < B.size(); ++i) B.data()[i] = value(gen);
  return B;
}

Eigen::VectorXf random_vector(Index n, std::mt19937& gen) {
  std::normal_distribution<float> value;
  Eigen::VectorXf w(n);
  for (Index i = 0; i < n; ++i) w(i) = value(gen);
  return w;
}

}  // namespace

TEST_CASE("the per-point kernels match a double reference for every column count modulo 8", "[kernels][reconstruction]") {
  std::mt19937 gen(7);
  for (Index p : {0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 15, 16, 17, 23, 31, 32, 33, 207, 260, 342, 567, 720}) {
    // Exactly 3p floats, so a masked tail that read past the rows would be
    // reading past the allocation (AddressSanitizer builds).
    const RowMatrixXf B = random_rows(3, p, gen);
    const Eigen::VectorXf w = random_vector(p, gen);
    std::vector<float> generic(3), sequential(3), interleaved(3);
    detail::rows3_dot_eigen(B.data(), p, w.data(), generic.data());
#ifdef QPREDUCE_HAVE_AVX2_KERNELS
    const bool have_avx2 = __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
    if (have_avx2) {
      detail::rows3_dot_avx2(B.data(), p, w.data(), sequential.data(), detail::RowOrder::Sequential, 4096);
      detail::rows3_dot_avx2(B.data(), p, w.data(), interleaved.data(), detail::RowOrder::Interleaved, 4096);
    }
#else
    const bool have_avx2 = false;
#endif
    for (int a = 0; a < 3; ++a) {
      const float* row = B.data() + a * p;
      const double exact = exact_dot(row, w.data(), p), bound = float_dot_bound(row, w.data(), p);
      INFO("p = " << p << ", row " << a);
      CHECK(std::abs(double(generic[a]) - exact) <= bound);
      if (have_avx2) {
        CHECK(std::abs(double(sequential[a]) - exact) <= bound);
        CHECK(std::abs(double(interleaved[a]) - exact) <= bound);
      }
    }
  }
}

TEST_CASE("reconstruct_points gives R·(B_v·w) per point, the same on any number of threads",
          "[reconstruction]") {
  std::mt19937 gen(11);
  // 3n·p floats: above the single-thread threshold; the larger one above
  // the 32 MiB where the kernel switches from the interleaved to the
  // sequential row order.
  const Index p = GENERATE(45, 203);
  const Index n = p == 45 ? 3001 : 14000;
  const RowMatrixXf B = random_rows(3 * n, p, gen);
  const Eigen::VectorXf w = random_vector(p, gen);
  const Eigen::Matrix3f R = Eigen::AngleAxisf(0.7f, Eigen::Vector3f(1, 2, 3).normalized()).toRotationMatrix();

  Points3d X;
  reconstruct_points(B, w, R, &X);
  REQUIRE(X.rows() == n);
  REQUIRE(X.allFinite());
  const Eigen::VectorXd flat = B.cast<double>() * w.cast<double>();
  const Eigen::Matrix3d Rd = R.cast<double>();
  double worst = 0.0;
  for (Index v = 0; v < n; ++v) {
    const Eigen::Vector3d exact = Rd * flat.segment<3>(3 * v);
    // Bound: the three row bounds through |R| (entries ≤ 1), plus the float
    // rounding of R·q.
    double bound = 0.0;
    for (int a = 0; a < 3; ++a) bound += float_dot_bound(B.data() + (3 * v + a) * p, w.data(), p);
    bound += 4.0 * std::ldexp(1.0, -23) * (flat.segment<3>(3 * v).cwiseAbs().sum() + 1e-30);
    const double err = (X.row(v).transpose() - exact).cwiseAbs().maxCoeff();
    worst = std::max(worst, err / bound);
  }
  CHECK(worst <= 1.0);

  const int saved = omp_get_max_threads();
  for (int threads : {1, 2, 3}) {
    omp_set_num_threads(threads);
    Points3d Y(7, 3);  // wrong row count: resized
    reconstruct_points(B, w, R, &Y);
    INFO("threads = " << threads);
    CHECK(Y.rows() == n);
    CHECK(Y == X);  // each point is one thread's work: bitwise the same
  }
  omp_set_num_threads(saved);
}

TEST_CASE("reconstruct_points in double gives scale·R·(B_v·w) + offset to double round-off", "[reconstruction]") {
  std::mt19937 gen(12);
  const Index n = 3001, p = 45;
  const RowMatrixXd B = random_rows(3 * n, p, gen).cast<double>();
  const Eigen::VectorXd w = random_vector(p, gen).cast<double>();
  const Eigen::Matrix3d R = Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  const Eigen::Vector3d offset(1e3, -2.0, 0.5);
  Points3d X;
  reconstruct_points(B, w, R, &X, 1e-4, offset);
  REQUIRE(X.rows() == n);
  double worst = 0.0;
  for (Index v = 0; v < n; ++v) {
    const Eigen::Vector3d q = B.middleRows(3 * v, 3) * w;
    const double scale = 1e-4 * (B.middleRows(3 * v, 3).cwiseAbs() * w.cwiseAbs()).maxCoeff() + offset.norm();
    worst = std::max(worst, (X.row(v).transpose() - (1e-4 * (R * q) + offset)).norm() / scale);
  }
  CHECK(worst <= 64 * p * std::numeric_limits<double>::epsilon());
  const int saved = omp_get_max_threads();
  omp_set_num_threads(1);
  Points3d Y;
  reconstruct_points(B, w, R, &Y, 1e-4, offset);
  omp_set_num_threads(saved);
  CHECK(Y == X);
  CHECK_THROWS_WITH(reconstruct_points(B, Eigen::VectorXd::Ones(3), R, &Y), Catch::Contains("w size"));
  Eigen::VectorXd bad = w;
  bad(2) = std::numeric_limits<double>::quiet_NaN();
  CHECK_THROWS_WITH(reconstruct_points(B, bad, R, &Y), Catch::Contains("w"));
  CHECK_THROWS_WITH(reconstruct_points(RowMatrixXd::Ones(5, p), w, R, &Y), Catch::Contains("multiple of 3"));
}

TEST_CASE("reconstruct_points handles empty inputs", "[reconstruction]") {
  Points3d X(5, 3);
  reconstruct_points(RowMatrixXf(0, 4), Eigen::VectorXf::Ones(4), Eigen::Matrix3f::Identity(), &X);
  CHECK(X.rows() == 0);
  // No reduced coordinates: every point is at the origin.
  reconstruct_points(RowMatrixXf(6, 0), Eigen::VectorXf(0), Eigen::Matrix3f::Identity(), &X);
  REQUIRE(X.rows() == 2);
  CHECK(X.isZero(0.0));
}

TEST_CASE("reconstruct_points rejects bad arguments with a message naming them", "[reconstruction][errors]") {
  const RowMatrixXf B = RowMatrixXf::Ones(6, 4);
  const Eigen::VectorXf w = Eigen::VectorXf::Ones(4);
  const Eigen::Matrix3f I = Eigen::Matrix3f::Identity();
  Points3d X;
  using Catch::Matchers::Contains;
  CHECK_THROWS_WITH(reconstruct_points(RowMatrixXf::Ones(5, 4), w, I, &X), Contains("multiple of 3"));
  CHECK_THROWS_WITH(reconstruct_points(B, Eigen::VectorXf::Ones(3), I, &X),
                    Contains("w size") && Contains("expected 4, got 3"));
  Eigen::VectorXf nan_w = w;
  nan_w(2) = std::numeric_limits<float>::quiet_NaN();
  CHECK_THROWS_WITH(reconstruct_points(B, nan_w, I, &X), Contains("w: contains NaN"));
  Eigen::Matrix3f inf_R = I;
  inf_R(1, 0) = std::numeric_limits<float>::infinity();
  CHECK_THROWS_WITH(reconstruct_points(B, w, inf_R, &X), Contains("R: contains NaN or infinite"));
  CHECK_THROWS_WITH(reconstruct_points(B, w, I, nullptr), Contains("X_out is null"));
  CHECK(X.rows() == 0);  // untouched by the failed calls
  Points3d Y(3, 3);
  CHECK_THROWS_WITH(reconstruct_points(B, w, I, Eigen::Map<Points3d>(Y.data(), 3, 3)),
                    Contains("X_out rows") && Contains("expected 2, got 3"));
}

TEST_CASE("reconstruct_points into a caller's buffer writes its n rows in place", "[reconstruction]") {
  std::mt19937 gen(5);
  const Index n = 40, p = 9;
  const RowMatrixXf B = random_rows(3 * n, p, gen);
  const Eigen::VectorXf w = random_vector(p, gen);
  const Eigen::Matrix3f R = Eigen::AngleAxisf(0.3f, Eigen::Vector3f::UnitZ()).toRotationMatrix();
  Points3d X;
  reconstruct_points(B, w, R, &X);
  Points3d buffer = Points3d::Constant(n + 1, 3, 5.0);  // one guard row after the n
  reconstruct_points(B, w, R, Eigen::Map<Points3d>(buffer.data(), n, 3));
  CHECK(buffer.topRows(n) == X);
  CHECK((buffer.row(n).array() == 5.0).all());
}
