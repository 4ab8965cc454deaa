// Riemannian Newton steps with Levenberg–Marquardt damping on stiff
// rotation sets (fused_steps.h; docs/engine.md, "Second-order steps").
#include "fused_steps.h"

#include "round_product.h"

#include <Eigen/Cholesky>
#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>

namespace qpreduce::detail {

using MatD = Matrix<double>;

namespace {

// With c = g′ − D∘y: the gradient in the tangent coordinates ω, and with
// `curvature` the blocks' curvature terms tr(M_a)·I − sym M_a, M_a = S_aᵀc_a.
void gradient_and_curvature(const Vector<double>& D, Index d, bool curvature, FusedWorkspace& W) {
  W.c = W.g - D.cwiseProduct(W.y_try);
  for (Index a = 0; a < d; ++a) {
    const Eigen::Map<const Eigen::Matrix3d> S(W.y_try.data() + 9 * a), C(W.c.data() + 9 * a);
    const Eigen::Matrix3d Ma = S.transpose() * C;
    W.grad.segment<3>(3 * a) = -Eigen::Vector3d(Ma(2, 1) - Ma(1, 2), Ma(0, 2) - Ma(2, 0), Ma(1, 0) - Ma(0, 1));
    if (curvature) W.curvature[static_cast<size_t>(a)] = Ma.trace() * Eigen::Matrix3d::Identity() -
                                                        0.5 * (Ma + Ma.transpose());
  }
}

// The model Hessian TᵀQT + the curvature terms at y_try (T_a the tangent
// basis vec(S_a·[e_i]×), Q = −(F − D)), symmetrised, into W.H.
void form_hessian(const MatD& F, const Vector<double>& D, Index d, FusedWorkspace& W) {
  for (Index a = 0; a < d; ++a) {
    const Eigen::Map<const Eigen::Matrix3d> S(W.y_try.data() + 9 * a);
    for (int i = 0; i < 3; ++i) {
      Eigen::Matrix3d Ei = Eigen::Matrix3d::Zero();  // [e_i]×
      Ei((i + 2) % 3, (i + 1) % 3) = 1.0;
      Ei((i + 1) % 3, (i + 2) % 3) = -1.0;
      Eigen::Map<Eigen::Matrix3d>(W.T.col(3 * a + i).data()) = S * Ei;
    }
    W.QT.middleCols(3 * a, 3).noalias() = -F.middleCols(9 * a, 9) * W.T.middleCols(3 * a, 3);
    W.QT.block(9 * a, 3 * a, 9, 3) += D.segment(9 * a, 9).asDiagonal() * W.T.middleCols(3 * a, 3);
  }
  for (Index a = 0; a < d; ++a)
    W.H.middleRows(3 * a, 3).noalias() = W.T.middleCols(3 * a, 3).transpose() * W.QT.middleRows(9 * a, 9);
  W.Hmu = W.H.transpose();  // symmetrise without a temporary (run does not allocate)
  W.H += W.Hmu;
  W.H *= 0.5;
  for (Index a = 0; a < d; ++a) W.H.block<3, 3>(3 * a, 3 * a) += W.curvature[static_cast<size_t>(a)];
}

// W.ldlt ← H + μI, with μ raised until it is positive definite; false
// after 60 raises.
bool damped_factor(double scale, double* mu, FusedWorkspace& W) {
  for (int tries = 0;; ++tries) {
    W.Hmu = W.H;
    W.Hmu.diagonal().array() += *mu;
    W.ldlt.compute(W.Hmu);
    if (W.ldlt.info() == Eigen::Success && W.ldlt.isPositive() && (W.ldlt.vectorD().array() > 0.0).all()) return true;
    *mu = std::max(4.0 * *mu, 1e-12 * scale);
    if (tries > 60) return false;
  }
}

// y_next = y_try with each block turned by its step, S_a·exp([ω_a]×).
void step_rotations(Index d, FusedWorkspace& W) {
  W.y_next = W.y_try;
  for (Index a = 0; a < d; ++a) {
    const Eigen::Vector3d w = W.omega.segment<3>(3 * a);
    const double angle = w.norm();
    if (angle == 0.0) continue;
    Eigen::Map<Eigen::Matrix3d> S(W.y_next.data() + 9 * a);
    S = (S * Eigen::AngleAxisd(angle, w / angle).toRotationMatrix()).eval();
  }
}

}  // namespace

AlternationResults run_second_order(const FusedModel& M, FusedWorkspace& W, InputProjection<double>& projection,
                                    const detail::PhaseOneEnergy& E, const Eigen::Ref<const Vector<double>>& b,
                                    const AlternationSettings& options, const detail::StopTest& stop,
                                    Eigen::Ref<Vector<double>> y) {
  const Index k = M.k(), d = k / 9;
  const MatD& F = M.explicit_rounds.F;  // F_y − A_yᵀΛ_y + D
  const Vector<double>& D = M.proximal_entries;
  constraint_term(E, b, true, W);
  double slack = 0.0;
  auto evaluate = [&](const Vector<double>& at) {  // W.g ← g′(at); returns (*)
    double_product(M, W, at.data(), 0, k, W.scratch.data());
    return reduced_energy(E, W, projection, b, at, false, &D, &slack);
  };
  AlternationResults summary;
  summary.second_order = true;
  W.y_try = y;
  double energy = evaluate(W.y_try);
  // μ is set from the Hessian's scale at the first step: the largest
  // ‖H_aa‖_F, which a rotation of the scene (H_aa ↦ G·H_aa·Gᵀ) keeps, so that
  // the damping, and with it the steps, do not depend on the axes.
  double mu = -1.0, scale = 0.0;
  bool hessian_current = false;
  for (int it = 0; it < options.iterations; ++it) {
    summary.iterations = it + 1;
    gradient_and_curvature(D, d, !hessian_current, W);
    if (!hessian_current) {
      form_hessian(F, D, d, W);
      hessian_current = true;
      if (mu < 0.0) {
        for (Index a = 0; a < d; ++a) scale = std::max(scale, W.H.block<3, 3>(3 * a, 3 * a).norm());
        scale = std::max(scale, 1e-300);
        mu = 1e-6 * scale;
      }
    }
    const double gnorm = W.grad.norm();
    if (!(gnorm > 0.0)) {  // stationary to the last bit
      summary.stop = RoundStop::Tolerance;
      break;
    }
    if (!damped_factor(scale, &mu, W)) return summary;  // cannot happen for finite H; keeps y
    W.omega = W.ldlt.solve(-W.grad);
    step_rotations(d, W);
    W.g_keep = W.g;
    const double next = evaluate(W.y_next);
    if (std::isfinite(next) && next <= energy + slack) {
      summary.last_change = (W.y_next - W.y_try).norm();
      W.y_try.swap(W.y_next);
      energy = next;
      mu = std::max(mu / 3.0, 1e-15 * scale);
      hessian_current = false;
      if (stop.done(summary.last_change, [&] { return W.y_try.norm(); }, &summary)) break;
    } else {
      summary.last_change = (W.y_next - W.y_try).norm();  // the step tried: a stalled run does not claim 0
      W.g.swap(W.g_keep);  // g′ of the kept y
      mu *= 4.0;
      ++summary.rejected;
      if (stop.spent(&summary)) break;
    }
  }
  y = W.y_try;
  summary.energy = energy;
  return summary;
}

void prepare_second_order(const FixedCoordinateSolver<double>& phase1, Index k, FusedWorkspace& W) {
  const Index d = k / 9, t = 3 * d, m = phase1.m();
  if (W.H.rows() != t) {
    W.c.resize(k);
    W.grad.resize(t);
    W.omega.resize(t);
    W.T.resize(9, t);
    W.QT.resize(k, t);
    W.H.resize(t, t);
    W.Hmu.resize(t, t);
    // (W.ldlt allocates on its first compute() and reuses that storage; it is
    // not assigned a sized LDLT here: Eigen's LDLT(Index) leaves its info
    // uninitialised, and the move would read it, which UBSan reports.)
    W.curvature.resize(static_cast<size_t>(d));
  }
  W.g_keep.resize(k);
  size_energy_workspace(k, m, W);
}

}  // namespace qpreduce::detail
