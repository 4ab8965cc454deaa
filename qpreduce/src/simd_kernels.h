// Private to the engine: the per-frame dense matrix–vector products.
//
// The engine is compiled for baseline x86-64, where Eigen's matrix–vector
// products use SSE2 without FMA and run compute-bound on the small dense
// operators of a frame (SubspaceSolver::solve's p × p M_q; FusedAlternation's
// q × k F_y). These kernels are compiled for
// AVX2 + FMA and chosen at run time when the CPU has both; otherwise Eigen's
// products are used. All matrices are column-major with leading dimension ld.
#pragma once

#include "qpreduce/common.h"
#include "qpreduce/util/cpu_features.h"

#include <algorithm>
#include <cassert>
#include <cstdlib>

#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#endif

namespace qpreduce::detail {

// The order in which rows3_dot_avx2 reads a point's three rows (below).
enum class RowOrder { Sequential, Interleaved };

#if defined(__x86_64__) && defined(__GNUC__)
#define QPREDUCE_HAVE_AVX2_KERNELS 1

__attribute__((target("avx2,fma"))) inline double hsum(__m256d v) {
  const __m128d lo = _mm256_castpd256_pd128(v), hi = _mm256_extractf128_pd(v, 1);
  const __m128d s = _mm_add_pd(lo, hi);
  return _mm_cvtsd_f64(_mm_add_sd(s, _mm_unpackhi_pd(s, s)));
}
__attribute__((target("avx2,fma"))) inline float hsum(__m256 v) {
  const __m128 lo = _mm256_castps256_ps128(v), hi = _mm256_extractf128_ps(v, 1);
  __m128 s = _mm_add_ps(lo, hi);
  s = _mm_add_ps(s, _mm_movehl_ps(s, s));
  s = _mm_add_ss(s, _mm_shuffle_ps(s, s, 1));
  return _mm_cvtss_f32(s);
}

// SIMD traits: 4 doubles or 8 floats per register.
template <typename T>
struct Avx;
template <>
struct Avx<double> {
  using V = __m256d;
  static constexpr int width = 4;
  __attribute__((target("avx2,fma"))) static V load(const double* p) { return _mm256_loadu_pd(p); }
  __attribute__((target("avx2,fma"))) static void store(double* p, V v) { _mm256_storeu_pd(p, v); }
  __attribute__((target("avx2,fma"))) static V set1(double a) { return _mm256_set1_pd(a); }
  __attribute__((target("avx2,fma"))) static V zero() { return _mm256_setzero_pd(); }
  __attribute__((target("avx2,fma"))) static V fma(V a, V b, V c) { return _mm256_fmadd_pd(a, b, c); }
  __attribute__((target("avx2,fma"))) static V add(V a, V b) { return _mm256_add_pd(a, b); }
};
template <>
struct Avx<float> {
  using V = __m256;
  static constexpr int width = 8;
  __attribute__((target("avx2,fma"))) static V load(const float* p) { return _mm256_loadu_ps(p); }
  __attribute__((target("avx2,fma"))) static void store(float* p, V v) { _mm256_storeu_ps(p, v); }
  __attribute__((target("avx2,fma"))) static V set1(float a) { return _mm256_set1_ps(a); }
  __attribute__((target("avx2,fma"))) static V zero() { return _mm256_setzero_ps(); }
  __attribute__((target("avx2,fma"))) static V fma(V a, V b, V c) { return _mm256_fmadd_ps(a, b, c); }
  __attribute__((target("avx2,fma"))) static V add(V a, V b) { return _mm256_add_ps(a, b); }
};

// y += M·x, M column-major rows × cols with leading dimension ld.
template <typename T>
__attribute__((target("avx2,fma"))) void gemv_add_avx2(const T* M, Index rows, Index cols, Index ld, const T* x,
                                                        T* y) {
  using A = Avx<T>;
  constexpr Index W = A::width;
  const Index vrows = rows - rows % W;
  Index j = 0;
  for (; j + 4 <= cols; j += 4) {
    const T* c0 = M + j * ld;
    const T* c1 = c0 + ld;
    const T* c2 = c1 + ld;
    const T* c3 = c2 + ld;
    const auto x0 = A::set1(x[j]), x1 = A::set1(x[j + 1]), x2 = A::set1(x[j + 2]), x3 = A::set1(x[j + 3]);
    for (Index i = 0; i < vrows; i += W) {
      auto acc = A::load(y + i);
      acc = A::fma(A::load(c0 + i), x0, acc);
      acc = A::fma(A::load(c1 + i), x1, acc);
      acc = A::fma(A::load(c2 + i), x2, acc);
      acc = A::fma(A::load(c3 + i), x3, acc);
      A::store(y + i, acc);
    }
    for (Index i = vrows; i < rows; ++i) y[i] += c0[i] * x[j] + c1[i] * x[j + 1] + c2[i] * x[j + 2] + c3[i] * x[j + 3];
  }
  for (; j < cols; ++j) {
    const T* c = M + j * ld;
    const auto xj = A::set1(x[j]);
    for (Index i = 0; i < vrows; i += W) A::store(y + i, A::fma(A::load(c + i), xj, A::load(y + i)));
    for (Index i = vrows; i < rows; ++i) y[i] += c[i] * x[j];
  }
}

// y = Mᵀ·x (y cols entries, overwritten) for a column-major block M (rows ×
// cols, leading dimension ld): one dot product a column, two accumulators.
// For the thin tall blocks of AndersonAcceleration (n × m, m ≤ 16), where
// Eigen's transposed product pays its blocking set-up on every call.
template <typename T>
__attribute__((target("avx2,fma"))) void gemtv_avx2(const T* M, Index rows, Index cols, Index ld, const T* x, T* y) {
  using A = Avx<T>;
  constexpr Index W = A::width;
  const Index vrows = rows - rows % W;
  for (Index j = 0; j < cols; ++j) {
    const T* c = M + j * ld;
    auto a = A::zero(), b = A::zero();
    Index i = 0;
    for (; i + 2 * W <= vrows; i += 2 * W) {
      a = A::fma(A::load(c + i), A::load(x + i), a);
      b = A::fma(A::load(c + i + W), A::load(x + i + W), b);
    }
    if (i < vrows) a = A::fma(A::load(c + i), A::load(x + i), a);
    T sum = hsum(A::add(a, b));
    for (i = vrows; i < rows; ++i) sum += c[i] * x[i];
    y[j] = sum;
  }
}

// y += M·x for symmetric M (n × n, leading dimension ld) of which only the
// lower triangle is read: four columns at a time, each below-diagonal entry
// is used twice (y_i += m_ij·x_j and y_j += m_ij·x_i).
template <typename T>
__attribute__((target("avx2,fma"))) void symv_lower_add_avx2(const T* M, Index n, Index ld, const T* x, T* y) {
  using A = Avx<T>;
  constexpr Index W = A::width;
  Index j = 0;
  for (; j + 4 <= n; j += 4) {
    // The 4 × 4 diagonal block.
    for (Index a = 0; a < 4; ++a)
      for (Index b = 0; b < 4; ++b) {
        const Index r = j + std::max(a, b), c = j + std::min(a, b);
        y[j + a] += M[r + c * ld] * x[j + b];
      }
    const T* c0 = M + j * ld;
    const T* c1 = c0 + ld;
    const T* c2 = c1 + ld;
    const T* c3 = c2 + ld;
    const auto x0 = A::set1(x[j]), x1 = A::set1(x[j + 1]), x2 = A::set1(x[j + 2]), x3 = A::set1(x[j + 3]);
    auto d0 = A::zero(), d1 = A::zero(), d2 = A::zero(), d3 = A::zero();
    Index i = j + 4;
    for (; i + W <= n; i += W) {
      const auto m0 = A::load(c0 + i), m1 = A::load(c1 + i), m2 = A::load(c2 + i), m3 = A::load(c3 + i);
      const auto xi = A::load(x + i);
      auto yi = A::load(y + i);
      yi = A::fma(m0, x0, yi);
      yi = A::fma(m1, x1, yi);
      yi = A::fma(m2, x2, yi);
      yi = A::fma(m3, x3, yi);
      A::store(y + i, yi);
      d0 = A::fma(m0, xi, d0);
      d1 = A::fma(m1, xi, d1);
      d2 = A::fma(m2, xi, d2);
      d3 = A::fma(m3, xi, d3);
    }
    T t0 = hsum(d0), t1 = hsum(d1), t2 = hsum(d2), t3 = hsum(d3);
    for (; i < n; ++i) {
      y[i] += c0[i] * x[j] + c1[i] * x[j + 1] + c2[i] * x[j + 2] + c3[i] * x[j + 3];
      t0 += c0[i] * x[i];
      t1 += c1[i] * x[i];
      t2 += c2[i] * x[i];
      t3 += c3[i] * x[i];
    }
    y[j] += t0;
    y[j + 1] += t1;
    y[j + 2] += t2;
    y[j + 3] += t3;
  }
  for (; j < n; ++j) {  // the last n mod 4 columns
    const T* c = M + j * ld;
    y[j] += c[j] * x[j];
    for (Index i = j + 1; i < n; ++i) {
      y[i] += c[i] * x[j];
      y[j] += c[i] * x[i];
    }
  }
}

// out(i, c) = Σ_t val[t]·panel(inner[t], c) over t ∈ [outer[i], outer[i+1]),
// for rows i ∈ [0, rows) and columns c < w: a compressed sparse row matrix
// times a row-major panel (leading dimension ldp ≥ 4·NV, padded with zeros),
// written to a column-major block (leading dimension ld). One nonzero is one
// broadcast and NV fused multiply-adds on a contiguous panel row.
template <int NV>
__attribute__((target("avx2,fma"))) void csr_times_panel_avx2(const int* outer, const int* inner, const double* val,
                                                              Index rows, const double* panel, Index ldp, Index w,
                                                              double* out, Index ld) {
  for (Index i = 0; i < rows; ++i) {
    __m256d acc[NV];
    for (int v = 0; v < NV; ++v) acc[v] = _mm256_setzero_pd();
    for (int t = outer[i]; t < outer[i + 1]; ++t) {
      const __m256d a = _mm256_set1_pd(val[t]);
      const double* row = panel + static_cast<Index>(inner[t]) * ldp;
      for (int v = 0; v < NV; ++v) acc[v] = _mm256_fmadd_pd(a, _mm256_loadu_pd(row + 4 * v), acc[v]);
    }
    alignas(32) double tmp[4 * NV];
    for (int v = 0; v < NV; ++v) _mm256_store_pd(tmp + 4 * v, acc[v]);
    for (Index c = 0; c < w; ++c) out[i + c * ld] = tmp[c];
  }
}

// The last 1–7 columns of a row by masked loads: kTailMask + 8 − r has its
// first r lanes set.
alignas(32) inline constexpr int kTailMask[16] = {-1, -1, -1, -1, -1, -1, -1, -1, 0, 0, 0, 0, 0, 0, 0, 0};

__attribute__((target("avx2,fma"))) inline __m256i tail_mask(Index r) {
  return _mm256_loadu_si256(reinterpret_cast<const __m256i*>(kTailMask + 8 - r));
}

// r·w for one row of p floats: two 8-wide accumulators, then the last p mod 8
// columns by a masked load (no scalar tail).
__attribute__((target("avx2,fma"))) inline float row_dot_avx2(const float* r, Index p, const float* w) {
  __m256 a = _mm256_setzero_ps(), b = a;
  Index j = 0;
  for (; j + 16 <= p; j += 16) {
    a = _mm256_fmadd_ps(_mm256_loadu_ps(r + j), _mm256_loadu_ps(w + j), a);
    b = _mm256_fmadd_ps(_mm256_loadu_ps(r + j + 8), _mm256_loadu_ps(w + j + 8), b);
  }
  if (j + 8 <= p) {
    a = _mm256_fmadd_ps(_mm256_loadu_ps(r + j), _mm256_loadu_ps(w + j), a);
    j += 8;
  }
  if (j < p) {
    const __m256i m = tail_mask(p - j);
    b = _mm256_fmadd_ps(_mm256_maskload_ps(r + j, m), _mm256_maskload_ps(w + j, m), b);
  }
  return hsum(_mm256_add_ps(a, b));
}

// out[a] = B_a·w (a = 0, 1, 2) for three consecutive rows B_a = B + a·p of a
// row-major float matrix: one point of reconstruct_points. Two orders:
//
// * Sequential: the rows one after the other (row_dot_avx2), so that the
//   point's 3p floats are read in address order. For DRAM-resident bases.
// * Interleaved: the three rows in one loop, six accumulators, each w load
//   shared by three rows, and each row's cache line `prefetch` bytes ahead
//   requested as it goes. For cache-resident bases, where the sequential
//   order's shorter dependency chains and unshared w loads cost 20–30%;
//   on DRAM-resident ones the three interleaved streams ran 15–25% slower
//   than the sequential order, with or without the prefetch
//   (docs/performance.md, "Reconstruction kernels").
__attribute__((target("avx2,fma"))) inline void rows3_dot_avx2(const float* B, Index p, const float* w, float* out,
                                                               RowOrder order, Index prefetch) {
  if (p == 0) {  // B may be null: no pointer arithmetic on it
    out[0] = out[1] = out[2] = 0.0f;
    return;
  }
  const float* r0 = B;
  const float* r1 = B + p;
  const float* r2 = B + 2 * p;
  if (order == RowOrder::Sequential) {
    out[0] = row_dot_avx2(r0, p, w);
    out[1] = row_dot_avx2(r1, p, w);
    out[2] = row_dot_avx2(r2, p, w);
    return;
  }
  auto ahead = [prefetch](const float* x) { return reinterpret_cast<const char*>(x) + prefetch; };
  __m256 a0 = _mm256_setzero_ps(), a1 = a0, a2 = a0, b0 = a0, b1 = a0, b2 = a0;
  Index j = 0;
  for (; j + 16 <= p; j += 16) {  // 64 bytes of each row: one prefetch each
    _mm_prefetch(ahead(r0 + j), _MM_HINT_T0);
    _mm_prefetch(ahead(r1 + j), _MM_HINT_T0);
    _mm_prefetch(ahead(r2 + j), _MM_HINT_T0);
    const __m256 w0 = _mm256_loadu_ps(w + j), w1 = _mm256_loadu_ps(w + j + 8);
    a0 = _mm256_fmadd_ps(_mm256_loadu_ps(r0 + j), w0, a0);
    a1 = _mm256_fmadd_ps(_mm256_loadu_ps(r1 + j), w0, a1);
    a2 = _mm256_fmadd_ps(_mm256_loadu_ps(r2 + j), w0, a2);
    b0 = _mm256_fmadd_ps(_mm256_loadu_ps(r0 + j + 8), w1, b0);
    b1 = _mm256_fmadd_ps(_mm256_loadu_ps(r1 + j + 8), w1, b1);
    b2 = _mm256_fmadd_ps(_mm256_loadu_ps(r2 + j + 8), w1, b2);
  }
  _mm_prefetch(ahead(r0 + j), _MM_HINT_T0);
  _mm_prefetch(ahead(r1 + j), _MM_HINT_T0);
  _mm_prefetch(ahead(r2 + j), _MM_HINT_T0);
  if (j + 8 <= p) {
    const __m256 w0 = _mm256_loadu_ps(w + j);
    a0 = _mm256_fmadd_ps(_mm256_loadu_ps(r0 + j), w0, a0);
    a1 = _mm256_fmadd_ps(_mm256_loadu_ps(r1 + j), w0, a1);
    a2 = _mm256_fmadd_ps(_mm256_loadu_ps(r2 + j), w0, a2);
    j += 8;
  }
  if (j < p) {
    const __m256i m = tail_mask(p - j);
    const __m256 w0 = _mm256_maskload_ps(w + j, m);
    b0 = _mm256_fmadd_ps(_mm256_maskload_ps(r0 + j, m), w0, b0);
    b1 = _mm256_fmadd_ps(_mm256_maskload_ps(r1 + j, m), w0, b1);
    b2 = _mm256_fmadd_ps(_mm256_maskload_ps(r2 + j, m), w0, b2);
  }
  out[0] = hsum(_mm256_add_ps(a0, b0));
  out[1] = hsum(_mm256_add_ps(a1, b1));
  out[2] = hsum(_mm256_add_ps(a2, b2));
}

// The one run-time test (qpreduce/util/cpu_features.h), honouring
// QPREDUCE_DISABLE_AVX2.
using qpreduce::cpu_has_avx2_fma;
#endif

// y += M·x for a column-major block M (rows × cols, leading dimension ld).
template <typename T>
void gemv_add(const T* M, Index rows, Index cols, Index ld, const T* x, T* y) {
#ifdef QPREDUCE_HAVE_AVX2_KERNELS
  if (cpu_has_avx2_fma()) {
    gemv_add_avx2(M, rows, cols, ld, x, y);
    return;
  }
#endif
  const Eigen::Map<const Matrix<T>, 0, Eigen::OuterStride<>> Mv(M, rows, cols, Eigen::OuterStride<>(ld));
  Eigen::Map<Vector<T>>(y, rows).noalias() += Mv * Eigen::Map<const Vector<T>>(x, cols);
}

// y = Mᵀ·x for a column-major block M (rows × cols, leading dimension ld).
template <typename T>
void gemtv(const T* M, Index rows, Index cols, Index ld, const T* x, T* y) {
#ifdef QPREDUCE_HAVE_AVX2_KERNELS
  if (cpu_has_avx2_fma()) {
    gemtv_avx2(M, rows, cols, ld, x, y);
    return;
  }
#endif
  const Eigen::Map<const Matrix<T>, 0, Eigen::OuterStride<>> Mv(M, rows, cols, Eigen::OuterStride<>(ld));
  Eigen::Map<Vector<T>>(y, cols).noalias() = Mv.transpose() * Eigen::Map<const Vector<T>>(x, rows);
}

// y = M·x (+ y when accumulate), M a whole column-major matrix.
template <typename T>
void gemv(const Matrix<T>& M, const T* x, T* y, bool accumulate) {
  if (!accumulate) Eigen::Map<Vector<T>>(y, M.rows()).setZero();
  gemv_add(M.data(), M.rows(), M.cols(), M.outerStride(), x, y);
}

// y += M·x for symmetric M, reading its lower triangle.
template <typename T>
void symv_lower_add(const Matrix<T>& M, const T* x, T* y) {
#ifdef QPREDUCE_HAVE_AVX2_KERNELS
  if (cpu_has_avx2_fma()) {
    symv_lower_add_avx2(M.data(), M.rows(), M.outerStride(), x, y);
    return;
  }
#endif
  const Eigen::Map<const Vector<T>> xv(x, M.cols());
  Eigen::Map<Vector<T>> yv(y, M.rows());
  yv.noalias() += M.template selfadjointView<Eigen::Lower>() * xv;
}


// out[a] = B_a·w for three consecutive rows of a row-major float matrix by
// Eigen's product: rows3_dot_avx2's fallback without AVX2 + FMA (the caller
// dispatches once, cpu_has_avx2_fma()).
inline void rows3_dot_eigen(const float* B, Index p, const float* w, float* out) {
  using Rows = Eigen::Matrix<float, 3, Eigen::Dynamic, Eigen::RowMajor>;
  Eigen::Map<Eigen::Vector3f>(out).noalias() = Eigen::Map<const Rows>(B, 3, p) * Eigen::Map<const Vector<float>>(w, p);
}

// out = S·B for a sparse matrix S stored by rows (n × m) and a column-major
// block B (m × w, w ≤ 32, leading dimension ldb), written to a column-major
// block (leading dimension ld). `panel` is scratch of at least m × 32
// doubles. B is copied into a row-major panel first, so that each nonzero of
// S costs one contiguous w-wide update instead of w strided ones (Eigen's
// column-major sparse × dense product).
inline void sparse_times_block(const Eigen::SparseMatrix<double, Eigen::RowMajor, int>& S, const double* B,
                               Index ldb, Index w, double* panel, double* out, Index ld) {
  const Index n = S.rows(), m = S.cols();
  assert(S.isCompressed() && w >= 0 && w <= 32);
  if (w == 0) return;
  const Index nv = (w + 3) / 4, ldp = 4 * nv;
  for (Index r = 0; r < m; ++r) {
    double* row = panel + r * ldp;
    for (Index c = 0; c < w; ++c) row[c] = B[r + c * ldb];
    for (Index c = w; c < ldp; ++c) row[c] = 0.0;
  }
  const int* outer = S.outerIndexPtr();
  const int* inner = S.innerIndexPtr();
  const double* val = S.valuePtr();
#ifdef QPREDUCE_HAVE_AVX2_KERNELS
  if (cpu_has_avx2_fma()) {
    switch (nv) {
      case 1: csr_times_panel_avx2<1>(outer, inner, val, n, panel, ldp, w, out, ld); return;
      case 2: csr_times_panel_avx2<2>(outer, inner, val, n, panel, ldp, w, out, ld); return;
      case 3: csr_times_panel_avx2<3>(outer, inner, val, n, panel, ldp, w, out, ld); return;
      case 4: csr_times_panel_avx2<4>(outer, inner, val, n, panel, ldp, w, out, ld); return;
      case 5: csr_times_panel_avx2<5>(outer, inner, val, n, panel, ldp, w, out, ld); return;
      case 6: csr_times_panel_avx2<6>(outer, inner, val, n, panel, ldp, w, out, ld); return;
      case 7: csr_times_panel_avx2<7>(outer, inner, val, n, panel, ldp, w, out, ld); return;
      default: csr_times_panel_avx2<8>(outer, inner, val, n, panel, ldp, w, out, ld); return;
    }
  }
#endif
  using RowPanel = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
  const Eigen::Map<const RowPanel, 0, Eigen::OuterStride<>> P(panel, m, w, Eigen::OuterStride<>(ldp));
  Eigen::Map<Matrix<double>, 0, Eigen::OuterStride<>> O(out, n, w, Eigen::OuterStride<>(ld));
  O.noalias() = S * P;  // row-major S and panel: contiguous panel rows
}

}  // namespace qpreduce::detail
