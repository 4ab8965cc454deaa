// The rotation fits of the local steps (arap_energy.h): the polar factor of
// a 3 × 3 matrix by Newton's iteration with an SVD fallback, in SIMD lanes
// for a batch of clusters, and the planar fit of flat elements.
#include "qpreduce/deform/energy/arap_energy.h"
#include "qpreduce/util/cpu_features.h"

#include <Eigen/Dense>
#include <Eigen/SVD>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
#include <immintrin.h>
#endif

namespace qpreduce::deform {

namespace {

Eigen::Matrix3d fit_rotation_svd(const Eigen::Matrix3d& G) {
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(G, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d U = svd.matrixU();
  const Eigen::Matrix3d Vm = svd.matrixV();
  if ((U * Vm.transpose()).determinant() < 0) U.col(2) *= -1.0;  // flip the smallest singular direction
  return U * Vm.transpose();
}

}  // namespace

namespace {

// fit_rotation's paths, shared with fit_rotations: the SVD below this
// det G / ‖G‖³, Newton steps on X = G·√3/‖G‖ when e² = ‖XᵀX − I‖²_F is
// below kNewtonE2, as many as newton_polar_steps says.
constexpr double kSingularDet = 1e-6;
constexpr double kNewtonE2 = 0.01;

// Newton steps until the a-priori bound e ← e²/(2(1 − e)) on the polar error
// of X (comment in fit_rotation) is below 1e-17, from e = √e².
int newton_polar_steps(double e2) {
  int steps = 0;
  for (double e = std::sqrt(e2); e > 1e-17; e = e * e / (2.0 * (1.0 - e))) ++steps;
  return steps;
}

}  // namespace

Eigen::Matrix3d fit_rotation(const Eigen::Matrix3d& G) {
  // det G > 0: the orthogonal polar factor of G is a rotation and maximises
  // tr(RᵀG). Well-conditioned G (λ_min(GᵀG) > 1e-4·λ_max, i.e. cond G < 100,
  // every Phase 2 input near a pose): R = G·M^(−1/2), M = GᵀG, from the
  // eigenvalues λ_i of M alone (Eigen's closed-form 3×3 solver, no
  // eigenvectors). With s_i = √λ_i and the invariants I₁ = Σs_i,
  // I₂ = s₁s₂ + s₁s₃ + s₂s₃, I₃ = s₁s₂s₃ of U = M^(1/2), Cayley–Hamilton gives
  //   U = (−M² + (I₁² − I₂)·M + I₁I₃·I) / (I₁I₂ − I₃),
  //   U⁻¹ = (M − I₁·U + I₂·I) / I₃            (Hoger & Carlson 1984).
  // Then one Newton step X ← ½(X + X⁻ᵀ) squares the remaining orthogonality
  // error (to ~1e-15). Worse-conditioned G take the scaled Newton iteration
  // X ← ½(γX + X⁻ᵀ/γ) (Higham); reflected or nearly singular G
  // (det G ≤ 1e-6·‖G‖³) the SVD path. Why not eigenvectors: docs/deform.md.
  //
  // Nearly conformal G (the retraction of an extrapolated rotation, a
  // Phase 2 input of a rigidly moved cluster with isotropic covariance):
  // X = G/r = Q·H with r² = ‖G‖²_F/3 (the mean squared singular value), H
  // symmetric positive definite and E = H − I small. A Newton step gives
  // Q·½(H + H⁻¹), whose E is ½E²H⁻¹ (any symmetric E):
  // ‖E′‖ ≤ ‖E‖²/(2(1 − ‖E‖)). ‖XᵀX − I‖_F = ‖E(2I + E)‖_F ≥ ‖E‖_F (the
  // eigenvalues of E are above −1) bounds ‖E‖ from the start, so the steps
  // run until that bound is below 1e-17: two to four inverses instead of the
  // eigenvalues (whose closed form costs an acos, a sincos and three square
  // roots). Scaling by ‖G‖ rather than ∛det G costs no cube root and makes
  // the same test the bound.
  const double norm = G.norm();
  // The polar factor of c·G (c > 0) is that of G: a G of extreme magnitude
  // (a covariance of a mesh in light-years or nanometres, up to ‖G‖⁴ below)
  // is scaled by a power of two first, exactly, so nothing overflows or
  // underflows.
  if (std::isfinite(norm) && norm > 0.0 && (norm > 1e50 || norm < 1e-50))
    return fit_rotation(std::ldexp(1.0, -std::ilogb(norm)) * G);
  const double det = G.determinant();
  if (!(det > kSingularDet * norm * norm * norm)) return fit_rotation_svd(G);
  const Eigen::Matrix3d M = G.transpose() * G;
  const double e2 = (M * (3.0 / (norm * norm)) - Eigen::Matrix3d::Identity()).squaredNorm();
  if (e2 < kNewtonE2) {
    Eigen::Matrix3d X = G * (std::sqrt(3.0) / norm);
    for (int step = newton_polar_steps(e2); step > 0; --step) X = 0.5 * (X + X.inverse().transpose());
    return X;
  }
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig;
  eig.computeDirect(M, Eigen::EigenvaluesOnly);
  const Eigen::Vector3d lambda = eig.eigenvalues();
  if (lambda.minCoeff() > 1e-4 * lambda.maxCoeff()) {
    const Eigen::Vector3d sv = lambda.cwiseSqrt();
    const double i1 = sv.sum(), i2 = sv(0) * sv(1) + sv(0) * sv(2) + sv(1) * sv(2), i3 = sv.prod();
    Eigen::Matrix3d U = (i1 * i1 - i2) * M - M * M;
    U.diagonal().array() += i1 * i3;
    U /= i1 * i2 - i3;
    Eigen::Matrix3d Uinv = M - i1 * U;
    Uinv.diagonal().array() += i2;
    const Eigen::Matrix3d X = G * (Uinv / i3);
    return 0.5 * (X + X.inverse().transpose());
  }
  Eigen::Matrix3d X = G;
  for (int it = 0; it < 30; ++it) {
    const Eigen::Matrix3d Xinv = X.inverse();
    const double gamma = std::sqrt(Xinv.norm() / X.norm());
    const Eigen::Matrix3d next = 0.5 * (gamma * X + Xinv.transpose() / gamma);
    const double step = (next - X).squaredNorm();
    X = next;
    if (step < 1e-30) return X;
  }
  return fit_rotation_svd(G);  // did not settle (never seen): exact fallback
}

namespace {

// Four blocks side by side: x[i][l] is entry i (column-major) of lane l's block.
constexpr int kLanes = 4;
using Lanes = double[9][kLanes];

// GCC makes an AVX2 + FMA copy of the lane loops too and picks it at load
// time (ifunc) by the CPU's features (x86-64-v3; "arch=haswell" would test
// for that Intel model and never pick it on an AMD CPU); elsewhere the
// compiler's default vector width.
#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__)
#define QPREDUCE_LANE_CLONES __attribute__((target_clones("arch=x86-64-v3", "default")))
#else
#define QPREDUCE_LANE_CLONES
#endif

// `steps` Newton steps X ← ½(X + X⁻ᵀ) in each lane, X⁻ᵀ = cof(X)/det X.
QPREDUCE_LANE_CLONES void newton_polar_lanes(Lanes& x, int steps) {
  for (int it = 0; it < steps; ++it) {
    for (int l = 0; l < kLanes; ++l) {
      const double a = x[0][l], d = x[1][l], g = x[2][l], b = x[3][l], e = x[4][l], h = x[5][l], c = x[6][l],
                   f = x[7][l], i = x[8][l];
      const double c00 = e * i - f * h, c01 = f * g - d * i, c02 = d * h - e * g;
      const double c10 = c * h - b * i, c11 = a * i - c * g, c12 = b * g - a * h;
      const double c20 = b * f - c * e, c21 = c * d - a * f, c22 = a * e - b * d;
      const double half_inv_det = 0.5 / (a * c00 + b * c01 + c * c02);
      x[0][l] = 0.5 * a + half_inv_det * c00;
      x[1][l] = 0.5 * d + half_inv_det * c10;
      x[2][l] = 0.5 * g + half_inv_det * c20;
      x[3][l] = 0.5 * b + half_inv_det * c01;
      x[4][l] = 0.5 * e + half_inv_det * c11;
      x[5][l] = 0.5 * h + half_inv_det * c21;
      x[6][l] = 0.5 * c + half_inv_det * c02;
      x[7][l] = 0.5 * f + half_inv_det * c12;
      x[8][l] = 0.5 * i + half_inv_det * c22;
    }
  }
}

// Per lane: ‖G‖², det G and e² = ‖GᵀG·3/‖G‖² − I‖²_F (fit_rotation's tests).
QPREDUCE_LANE_CLONES void conformality_lanes(const Lanes& x, double* norm2, double* det, double* e2) {
  for (int l = 0; l < kLanes; ++l) {
    const double a = x[0][l], d = x[1][l], g = x[2][l], b = x[3][l], e = x[4][l], h = x[5][l], c = x[6][l],
                 f = x[7][l], i = x[8][l];
    const double n2 = a * a + b * b + c * c + d * d + e * e + f * f + g * g + h * h + i * i;
    det[l] = a * (e * i - f * h) + b * (f * g - d * i) + c * (d * h - e * g);
    // M = GᵀG: column j of G is (x[3j], x[3j+1], x[3j+2]).
    const double m00 = a * a + d * d + g * g, m11 = b * b + e * e + h * h, m22 = c * c + f * f + i * i;
    const double m01 = a * b + d * e + g * h, m02 = a * c + d * f + g * i, m12 = b * c + e * f + h * i;
    const double s = 3.0 / n2;
    const double r0 = s * m00 - 1.0, r1 = s * m11 - 1.0, r2 = s * m22 - 1.0;
    e2[l] = r0 * r0 + r1 * r1 + r2 * r2 + 2.0 * s * s * (m01 * m01 + m02 * m02 + m12 * m12);
    norm2[l] = n2;
  }
}

// fit_rotations_near's start in each lane: r (the start s_a) scaled to a
// rotation's size, r ← s·√(3/‖s‖²), and usable[l] = 1 when Newton's method
// may start there, else 0: G of moderate size (the adjugate below is
// quadratic, det A cubic in G) and the start's direction a rotation to
// round-off (a rotation or a scaled one, as the rounds keep them).
QPREDUCE_LANE_CLONES void start_lanes(const Lanes& g, Lanes& r, double* usable) {
  for (int l = 0; l < kLanes; ++l) {
    double gn2 = 0.0, sn2 = 0.0;
    for (int i = 0; i < 9; ++i) {
      gn2 += g[i][l] * g[i][l];
      sn2 += r[i][l] * r[i][l];
    }
    const double scale = std::sqrt(3.0 / sn2);
    for (int i = 0; i < 9; ++i) r[i][l] *= scale;
    const double a = r[0][l], d = r[1][l], g0 = r[2][l], b = r[3][l], e = r[4][l], h = r[5][l], c = r[6][l],
                 f = r[7][l], i = r[8][l];
    const double det = a * (e * i - f * h) + b * (f * g0 - d * i) + c * (d * h - e * g0);
    // ‖RᵀR − I‖²_F: column j of R is (r[3j], r[3j+1], r[3j+2]).
    const double m00 = a * a + d * d + g0 * g0 - 1.0, m11 = b * b + e * e + h * h - 1.0,
                 m22 = c * c + f * f + i * i - 1.0;
    const double m01 = a * b + d * e + g0 * h, m02 = a * c + d * f + g0 * i, m12 = b * c + e * f + h * i;
    const double off2 = m00 * m00 + m11 * m11 + m22 * m22 + 2.0 * (m01 * m01 + m02 * m02 + m12 * m12);
    const bool ok = gn2 > 1e-100 && gn2 < 1e100 && sn2 > 0.0 && sn2 <= std::numeric_limits<double>::max() &&
                    det > 0.0 && off2 <= 1e-26;
    usable[l] = ok ? 1.0 : 0.0;
  }
}

// fit_rotations_near's step: Newton's method on SO(3) for max tr(RᵀG) in
// each lane still active. With X = RᵀG, f(ω) = tr((R·exp[ω])ᵀG) =
// f(0) + ωᵀb − ½ωᵀAω + O(ω³), b = axial(X − Xᵀ), A = tr(X)·I − sym(X): the
// step ω = A⁻¹b, taken by the Cayley rotation C = (I − [h])⁻¹(I + [h]) =
// I + 2([h] + [h]²)/(1 + |h|²), h = ω/2 (equal to exp[ω] to second order: the
// convergence stays quadratic). A lane whose A is not positive definite
// (det A ≤ kNearPd·tr(A)³: a start far from the maximum, or a G whose
// nearest rotation is not unique) or whose step exceeds kNearStep² in |ω|²
// is marked failed; a lane stops (active = 0) once |ω|² ≤ kNearDone, after
// that step. Failed and stopped lanes take ω = 0, C = I exactly, so R keeps
// its bits and a lane's result does not depend on the other lanes.
constexpr double kNearPd = 1e-9;
constexpr double kNearStep = 1.0;
constexpr double kNearDone = 1e-22;

void rotation_newton_scalar(const Lanes& g, Lanes& r, double* active, double* failed) {
  for (int l = 0; l < kLanes; ++l) {
    double x[9];  // X = RᵀG, column-major
    for (int j = 0; j < 3; ++j)
      for (int i = 0; i < 3; ++i)
        x[i + 3 * j] =
            r[3 * i][l] * g[3 * j][l] + r[3 * i + 1][l] * g[3 * j + 1][l] + r[3 * i + 2][l] * g[3 * j + 2][l];
    const double tr = x[0] + x[4] + x[8];
    const double b0 = x[5] - x[7], b1 = x[6] - x[2], b2 = x[1] - x[3];
    const double a00 = tr - x[0], a11 = tr - x[4], a22 = tr - x[8];
    const double a01 = -0.5 * (x[1] + x[3]), a02 = -0.5 * (x[2] + x[6]), a12 = -0.5 * (x[5] + x[7]);
    const double c00 = a11 * a22 - a12 * a12, c01 = a02 * a12 - a01 * a22, c02 = a01 * a12 - a02 * a11;
    const double c11 = a00 * a22 - a02 * a02, c12 = a01 * a02 - a00 * a12, c22 = a00 * a11 - a01 * a01;
    const double det = a00 * c00 + a01 * c01 + a02 * c02, scale = a00 + a11 + a22;
    const bool pd = a00 > 0.0 && c22 > 0.0 && det > kNearPd * scale * scale * scale;
    const double inv = pd ? 1.0 / det : 0.0;
    double w0 = (c00 * b0 + c01 * b1 + c02 * b2) * inv, w1 = (c01 * b0 + c11 * b1 + c12 * b2) * inv,
           w2 = (c02 * b0 + c12 * b1 + c22 * b2) * inv;
    const double n2 = w0 * w0 + w1 * w1 + w2 * w2;
    const bool ok = pd && n2 <= kNearStep * kNearStep;
    const bool move = active[l] != 0.0 && ok;
    failed[l] = active[l] != 0.0 && !ok ? 1.0 : failed[l];
    active[l] = move && n2 > kNearDone ? 1.0 : 0.0;
    const double m = move ? 0.5 : 0.0;  // h = ω/2, or 0
    w0 *= m;
    w1 *= m;
    w2 *= m;
    const double hh = w0 * w0 + w1 * w1 + w2 * w2, s = 2.0 / (1.0 + hh);
    // C = I + s·([h] + hhᵀ − |h|²I), column-major.
    const double c[9] = {1.0 + s * (w0 * w0 - hh), s * (w2 + w0 * w1),       s * (-w1 + w0 * w2),
                         s * (-w2 + w0 * w1),      1.0 + s * (w1 * w1 - hh), s * (w0 + w1 * w2),
                         s * (w1 + w0 * w2),       s * (-w0 + w1 * w2),      1.0 + s * (w2 * w2 - hh)};
    double next[9];
    for (int j = 0; j < 3; ++j)
      for (int i = 0; i < 3; ++i)
        next[i + 3 * j] = r[i][l] * c[3 * j] + r[i + 3][l] * c[3 * j + 1] + r[i + 6][l] * c[3 * j + 2];
    for (int i = 0; i < 9; ++i) r[i][l] = next[i];
  }
}

#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
#define QPREDUCE_ROTATION_LANES_AVX2 1
// a·b − c·d, and s·(q + l): rotation_newton_avx2's pieces.
__attribute__((target("avx2,fma"))) inline __m256d msub(__m256d a, __m256d b, __m256d c, __m256d d) {
  return _mm256_fmsub_pd(a, b, _mm256_mul_pd(c, d));
}
__attribute__((target("avx2,fma"))) inline __m256d entry(__m256d s, __m256d quadratic, __m256d linear) {
  return _mm256_mul_pd(s, _mm256_add_pd(quadratic, linear));
}

// rotation_newton_scalar in AVX2 + FMA: one lane per vector entry.
__attribute__((target("avx2,fma"))) void rotation_newton_avx2(const Lanes& g, Lanes& r, double* active,
                                                              double* failed) {
  __m256d G[9], R[9], x[9];
  for (int i = 0; i < 9; ++i) {
    G[i] = _mm256_load_pd(g[i]);
    R[i] = _mm256_load_pd(r[i]);
  }
  for (int j = 0; j < 3; ++j)
    for (int i = 0; i < 3; ++i)
      x[i + 3 * j] = _mm256_fmadd_pd(R[3 * i + 2], G[3 * j + 2],
                                     _mm256_fmadd_pd(R[3 * i + 1], G[3 * j + 1], _mm256_mul_pd(R[3 * i], G[3 * j])));
  const __m256d half = _mm256_set1_pd(0.5), zero = _mm256_setzero_pd(), one = _mm256_set1_pd(1.0);
  const __m256d tr = _mm256_add_pd(_mm256_add_pd(x[0], x[4]), x[8]);
  const __m256d b0 = _mm256_sub_pd(x[5], x[7]), b1 = _mm256_sub_pd(x[6], x[2]), b2 = _mm256_sub_pd(x[1], x[3]);
  const __m256d a00 = _mm256_sub_pd(tr, x[0]), a11 = _mm256_sub_pd(tr, x[4]), a22 = _mm256_sub_pd(tr, x[8]);
  const __m256d a01 = _mm256_mul_pd(_mm256_set1_pd(-0.5), _mm256_add_pd(x[1], x[3]));
  const __m256d a02 = _mm256_mul_pd(_mm256_set1_pd(-0.5), _mm256_add_pd(x[2], x[6]));
  const __m256d a12 = _mm256_mul_pd(_mm256_set1_pd(-0.5), _mm256_add_pd(x[5], x[7]));
  const __m256d c00 = msub(a11, a22, a12, a12), c01 = msub(a02, a12, a01, a22), c02 = msub(a01, a12, a02, a11);
  const __m256d c11 = msub(a00, a22, a02, a02), c12 = msub(a01, a02, a00, a12), c22 = msub(a00, a11, a01, a01);
  const __m256d det = _mm256_fmadd_pd(a02, c02, _mm256_fmadd_pd(a01, c01, _mm256_mul_pd(a00, c00)));
  const __m256d scale = _mm256_add_pd(_mm256_add_pd(a00, a11), a22);
  const __m256d floor = _mm256_mul_pd(_mm256_set1_pd(kNearPd), _mm256_mul_pd(scale, _mm256_mul_pd(scale, scale)));
  const __m256d pd =
      _mm256_and_pd(_mm256_and_pd(_mm256_cmp_pd(a00, zero, _CMP_GT_OQ), _mm256_cmp_pd(c22, zero, _CMP_GT_OQ)),
                    _mm256_cmp_pd(det, floor, _CMP_GT_OQ));
  const __m256d inv = _mm256_and_pd(_mm256_div_pd(one, det), pd);
  __m256d w0 = _mm256_mul_pd(_mm256_fmadd_pd(c02, b2, _mm256_fmadd_pd(c01, b1, _mm256_mul_pd(c00, b0))), inv);
  __m256d w1 = _mm256_mul_pd(_mm256_fmadd_pd(c12, b2, _mm256_fmadd_pd(c11, b1, _mm256_mul_pd(c01, b0))), inv);
  __m256d w2 = _mm256_mul_pd(_mm256_fmadd_pd(c22, b2, _mm256_fmadd_pd(c12, b1, _mm256_mul_pd(c02, b0))), inv);
  const __m256d n2 = _mm256_fmadd_pd(w2, w2, _mm256_fmadd_pd(w1, w1, _mm256_mul_pd(w0, w0)));
  const __m256d ok = _mm256_and_pd(pd, _mm256_cmp_pd(n2, _mm256_set1_pd(kNearStep * kNearStep), _CMP_LE_OQ));
  const __m256d act = _mm256_cmp_pd(_mm256_load_pd(active), zero, _CMP_NEQ_OQ);
  const __m256d move = _mm256_and_pd(act, ok);
  _mm256_store_pd(failed, _mm256_blendv_pd(_mm256_load_pd(failed), one, _mm256_andnot_pd(ok, act)));
  _mm256_store_pd(active,
                  _mm256_and_pd(one, _mm256_and_pd(move, _mm256_cmp_pd(n2, _mm256_set1_pd(kNearDone), _CMP_GT_OQ))));
  const __m256d m = _mm256_and_pd(half, move);
  w0 = _mm256_mul_pd(w0, m);
  w1 = _mm256_mul_pd(w1, m);
  w2 = _mm256_mul_pd(w2, m);
  const __m256d hh = _mm256_fmadd_pd(w2, w2, _mm256_fmadd_pd(w1, w1, _mm256_mul_pd(w0, w0)));
  const __m256d sc = _mm256_div_pd(_mm256_set1_pd(2.0), _mm256_add_pd(one, hh));
  const __m256d c[9] = {_mm256_add_pd(one, entry(sc, _mm256_mul_pd(w0, w0), _mm256_sub_pd(zero, hh))),
                        entry(sc, _mm256_mul_pd(w0, w1), w2),
                        entry(sc, _mm256_mul_pd(w0, w2), _mm256_sub_pd(zero, w1)),
                        entry(sc, _mm256_mul_pd(w0, w1), _mm256_sub_pd(zero, w2)),
                        _mm256_add_pd(one, entry(sc, _mm256_mul_pd(w1, w1), _mm256_sub_pd(zero, hh))),
                        entry(sc, _mm256_mul_pd(w1, w2), w0),
                        entry(sc, _mm256_mul_pd(w0, w2), w1),
                        entry(sc, _mm256_mul_pd(w1, w2), _mm256_sub_pd(zero, w0)),
                        _mm256_add_pd(one, entry(sc, _mm256_mul_pd(w2, w2), _mm256_sub_pd(zero, hh)))};
  for (int j = 0; j < 3; ++j)
    for (int i = 0; i < 3; ++i)
      _mm256_store_pd(r[i + 3 * j],
                      _mm256_fmadd_pd(R[i + 6], c[3 * j + 2],
                                      _mm256_fmadd_pd(R[i + 3], c[3 * j + 1], _mm256_mul_pd(R[i], c[3 * j]))));
}
#endif

void rotation_newton_lanes(const Lanes& g, Lanes& r, double* active, double* failed) {
#ifdef QPREDUCE_ROTATION_LANES_AVX2
  if (cpu_has_avx2_fma()) return rotation_newton_avx2(g, r, active, failed);
#endif
  rotation_newton_scalar(g, r, active, failed);
}

}  // namespace

void fit_rotations(double* s, Index d, double* trace) {
  for (Index a0 = 0; a0 < d; a0 += kLanes) {
    const int lanes = static_cast<int>(std::min<Index>(kLanes, d - a0));
    alignas(32) Lanes x;
    for (int l = 0; l < lanes; ++l)
      for (int i = 0; i < 9; ++i) x[i][l] = s[9 * (a0 + l) + i];
    for (int l = lanes; l < kLanes; ++l)  // a partial group: identities in the idle lanes
      for (int i = 0; i < 9; ++i) x[i][l] = i % 4 == 0 ? 1.0 : 0.0;
    double norm2[kLanes], det[kLanes], e2[kLanes];
    conformality_lanes(x, norm2, det, e2);
    bool newton[kLanes];
    double worst = 0.0;  // the largest e² of the lanes taking Newton steps
    for (int l = 0; l < kLanes; ++l) {
      const double norm = std::sqrt(norm2[l]);
      newton[l] = det[l] > kSingularDet * norm * norm * norm && e2[l] < kNewtonE2;
      if (!newton[l]) {  // fit_rotation below; the identity meanwhile
        for (int i = 0; i < 9; ++i) x[i][l] = i % 4 == 0 ? 1.0 : 0.0;
        continue;
      }
      worst = std::max(worst, e2[l]);
      const double scale = std::sqrt(3.0) / norm;
      for (int i = 0; i < 9; ++i) x[i][l] *= scale;
    }
    // The worst lane's steps: the bound grows with e, so no lane needs more.
    newton_polar_lanes(x, newton_polar_steps(worst));
    for (int l = 0; l < lanes; ++l) {
      double* block = s + 9 * (a0 + l);
      Eigen::Map<Eigen::Matrix3d> G(block);
      if (newton[l]) {
        if (trace) {
          double t = 0.0;
          for (int i = 0; i < 9; ++i) t += x[i][l] * block[i];
          trace[a0 + l] = t;
        }
        for (int i = 0; i < 9; ++i) block[i] = x[i][l];
      } else {
        const Eigen::Matrix3d R = fit_rotation(G);
        if (trace) trace[a0 + l] = R.cwiseProduct(G).sum();
        G = R;
      }
    }
  }
}

Eigen::Matrix3d fit_rotation_planar(const Eigen::Matrix3d& G, const Eigen::Vector3d& n) {
  // t₁ ⟂ n from the axis n is least aligned with, t₂ = n × t₁.
  Eigen::Index axis = 0;
  n.cwiseAbs().minCoeff(&axis);
  const Eigen::Vector3d t1 = n.cross(Eigen::Vector3d::Unit(axis)).normalized();
  const Eigen::Vector3d t2 = n.cross(t1);
  Eigen::Matrix<double, 3, 2> A;
  A.col(0) = G * t1;
  A.col(1) = G * t2;
  const Eigen::Matrix2d M = A.transpose() * A;
  const double det = M.determinant(), trace = M.trace();
  if (!(det > 1e-6 * trace * trace)) return fit_rotation(G);  // σ₁σ₂ ≤ 1e-3·(σ₁² + σ₂²)
  // √M = (M + √det·I)/√(tr M + 2√det) for a 2 × 2 SPD M.
  const double s = std::sqrt(det);
  Eigen::Matrix2d root = M;
  root.diagonal().array() += s;
  root /= std::sqrt(trace + 2.0 * s);
  const Eigen::Matrix<double, 3, 2> W = A * root.inverse();
  Eigen::Matrix3d R = W.col(0) * t1.transpose() + W.col(1) * t2.transpose();
  R.noalias() += W.col(0).cross(W.col(1)) * n.transpose();
  return R;
}

Index fit_rotations_near(const double* G, const double* start, double* t, Index d) {
  // Newton from the start until every lane has stopped or failed; at most
  // kSteps steps (from a start within a tenth of a radian: three or four).
  constexpr int kSteps = 8;
  Index fallbacks = 0;
  for (Index a0 = 0; a0 < d; a0 += kLanes) {
    const int lanes = static_cast<int>(std::min<Index>(kLanes, d - a0));
    alignas(32) Lanes g, r;
    alignas(32) double active[kLanes], failed[kLanes];
    for (int l = 0; l < kLanes; ++l) {
      active[l] = 0.0;
      failed[l] = 0.0;
      for (int i = 0; i < 9; ++i) {
        const bool used = l < lanes;
        g[i][l] = used ? G[9 * (a0 + l) + i] : (i % 4 == 0 ? 1.0 : 0.0);
        r[i][l] = used ? start[9 * (a0 + l) + i] : (i % 4 == 0 ? 1.0 : 0.0);
      }
    }
    // The idle lanes of a partial group hold identities: they stay inactive
    // and are never read. An unusable lane takes identities too, so that no
    // lane computes with a start or a G out of range.
    alignas(32) double usable[kLanes];
    start_lanes(g, r, usable);
    for (int l = 0; l < lanes; ++l) {
      active[l] = usable[l];
      failed[l] = 1.0 - usable[l];
      if (usable[l] == 0.0)
        for (int i = 0; i < 9; ++i) g[i][l] = r[i][l] = i % 4 == 0 ? 1.0 : 0.0;
    }
    for (int step = 0; step < kSteps; ++step) {
      rotation_newton_lanes(g, r, active, failed);
      if (std::all_of(active, active + kLanes, [](double v) { return v == 0.0; })) break;
    }
    for (int l = 0; l < lanes; ++l) {
      Eigen::Map<Eigen::Matrix3d> out(t + 9 * (a0 + l));
      if (failed[l] != 0.0 || active[l] != 0.0) {
        ++fallbacks;
        out = fit_rotation(Eigen::Map<const Eigen::Matrix3d>(G + 9 * (a0 + l)));
      } else {
        for (int i = 0; i < 9; ++i) out(i) = r[i][l];
      }
    }
  }
  return fallbacks;
}

}  // namespace qpreduce::deform
