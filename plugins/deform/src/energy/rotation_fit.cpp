// The rotation fits of the local steps (arap_energy.h): the polar factor of
// a 3 × 3 matrix by Newton's iteration with an SVD fallback, in SIMD lanes
// for a batch of clusters, and the planar fit of flat elements.
#include "qpreduce/deform/energy/arap_energy.h"

#include <Eigen/Dense>
#include <Eigen/SVD>

#include <algorithm>
#include <array>
#include <cmath>

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
// time (ifunc); elsewhere the compiler's default vector width.
#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__)
#define QPREDUCE_LANE_CLONES __attribute__((target_clones("arch=haswell", "default")))
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

}  // namespace qpreduce::deform
