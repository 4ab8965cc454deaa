// Private to the engine: the few large dense products of a build go through
// the system BLAS (the one CHOLMOD links; OpenBLAS on Debian, which picks its
// kernels for the CPU at run time). The engine itself is compiled for
// baseline x86-64, where Eigen's own GEMM kernels use SSE2 only — about a
// third of the speed of OpenBLAS's AVX2/FMA kernels on the n × p products.
#pragma once

#include "qpreduce/common.h"

#include <cassert>
#include <type_traits>

extern "C" void dgemm_(const char* transa, const char* transb, const int* m, const int* n, const int* k,
                       const double* alpha, const double* a, const int* lda, const double* b, const int* ldb,
                       const double* beta, double* c, const int* ldc);
extern "C" void sgemm_(const char* transa, const char* transb, const int* m, const int* n, const int* k,
                       const float* alpha, const float* a, const int* lda, const float* b, const int* ldb,
                       const float* beta, float* c, const int* ldc);

extern "C" void dtrsm_(const char* side, const char* uplo, const char* transa, const char* diag, const int* m,
                       const int* n, const double* alpha, const double* a, const int* lda, double* b, const int* ldb);

namespace qpreduce::detail {

// C = alpha·op(A)·op(B) + beta·C for column-major double (dgemm) or float
// (sgemm) blocks with unit inner stride (whole matrices, middleRows/
// middleCols/block of them).
template <typename MA, typename MB, typename MC>
void blas_gemm(bool transpose_a, bool transpose_b, double alpha, const MA& A, const MB& B, double beta, MC&& C) {
  const int m = static_cast<int>(C.rows()), n = static_cast<int>(C.cols());
  const int k = static_cast<int>(transpose_a ? A.rows() : A.cols());
  assert((transpose_a ? A.cols() : A.rows()) == m && (transpose_b ? B.rows() : B.cols()) == n &&
         (transpose_b ? B.cols() : B.rows()) == k);
  assert(A.innerStride() == 1 && B.innerStride() == 1 && C.innerStride() == 1);
  if (m == 0 || n == 0) return;
  if (k == 0) {
    if (beta == 0.0) C.setZero();
    else C *= beta;
    return;
  }
  const char ta = transpose_a ? 'T' : 'N', tb = transpose_b ? 'T' : 'N';
  const int lda = static_cast<int>(A.outerStride()), ldb = static_cast<int>(B.outerStride());
  const int ldc = static_cast<int>(C.outerStride());
  using Scalar = typename std::decay_t<MC>::Scalar;
  static_assert(std::is_same_v<Scalar, double> || std::is_same_v<Scalar, float>, "blas_gemm: double or float");
  static_assert(std::is_same_v<typename MA::Scalar, Scalar> && std::is_same_v<typename MB::Scalar, Scalar>,
                "blas_gemm: A, B and C of one scalar type");
  if constexpr (std::is_same_v<Scalar, double>) {
    dgemm_(&ta, &tb, &m, &n, &k, &alpha, A.data(), &lda, B.data(), &ldb, &beta, C.data(), &ldc);
  } else {
    const float a = static_cast<float>(alpha), b = static_cast<float>(beta);
    sgemm_(&ta, &tb, &m, &n, &k, &a, A.data(), &lda, B.data(), &ldb, &b, C.data(), &ldc);
  }
}

// B ← L⁻¹·B with L the lower triangle of `L` (k × k, its diagonal nonzero;
// the strict upper triangle is not read) and B k × n, column-major double
// with unit inner stride (dtrsm).
template <typename ML, typename MB>
void blas_lower_solve(const ML& L, MB&& B) {
  const int k = static_cast<int>(B.rows()), n = static_cast<int>(B.cols());
  assert(L.rows() == k && L.cols() == k && L.innerStride() == 1 && B.innerStride() == 1);
  static_assert(std::is_same_v<typename ML::Scalar, double> &&
                    std::is_same_v<typename std::decay_t<MB>::Scalar, double>,
                "blas_lower_solve: double");
  if (k == 0 || n == 0) return;
  const double one = 1.0;
  const int lda = static_cast<int>(L.outerStride()), ldb = static_cast<int>(B.outerStride());
  dtrsm_("L", "L", "N", "N", &k, &n, &one, L.data(), &lda, B.data(), &ldb);
}

// Sets the BLAS's own thread count for the scope when it is OpenBLAS (looked
// up at run time; with another BLAS this does nothing) and restores it after.
// Used around OpenMP loops that call the BLAS from every thread, so that the
// two levels do not oversubscribe the cores. OpenBLAS's setting is process-
// wide: another thread calling the BLAS meanwhile runs single-threaded too.
class ScopedBlasThreads {
 public:
  explicit ScopedBlasThreads(int threads);
  ~ScopedBlasThreads();
  ScopedBlasThreads(const ScopedBlasThreads&) = delete;
  ScopedBlasThreads& operator=(const ScopedBlasThreads&) = delete;

 private:
  void (*set_)(int) = nullptr;
  int previous_ = 0;
};

}  // namespace qpreduce::detail
