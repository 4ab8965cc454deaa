// LocalGlobalArap's solve (local_global_rounds.h): the constraint values,
// the Newton steps on the classic energy, and the rounds with Anderson
// acceleration (SafeguardedAnderson) and the stop tests.
#include "local_global_rounds.h"

#include <fmt/format.h>

namespace qpreduce::deform::detail_reference {

ConstrainedValues constrained_values(const LocalGlobalState& st, const HandleTargets& targets,
                                     const Eigen::Matrix3d& frame) {
  const PreparedModel& m = st.m;
  const Eigen::Matrix3d Ft = frame.transpose();
  ConstrainedValues cv;
  cv.up.resize(static_cast<Index>(st.pinned_rows.size()));
  {
    Eigen::VectorXd u = Eigen::VectorXd::Zero(st.nu);
    for (const auto& pt : detail_reference::patch_targets(m, st.handles, targets, frame)) {
      const Index base = st.nu - 12 * st.s + 12 * pt.patch;
      for (int a = 0; a < 3; ++a)
        for (int c = 0; c < 3; ++c) u(base + 3 * a + c) = pt.transform(a, c);
      u.segment<3>(base + 9) = pt.transform.col(3);
    }
    for (size_t h = 0; h < st.handles.points.size(); ++h) {
      const PointHandle& ph = st.handles.points[h];
      if (ph.vertices.size() != 1 || m.patch_of_vertex[ph.vertices[0]] >= 0) continue;
      if (!(ph.weights.empty() || ph.weights[0] == 1.0)) continue;
      u.segment<3>(st.control_of_free[ph.vertices[0]]) = Ft * targets.points.row(static_cast<Index>(h)).transpose();
    }
    for (size_t k = 0; k < st.pinned_rows.size(); ++k) cv.up(static_cast<Index>(k)) = u(st.pinned_rows[k]);
  }
  cv.bg.resize(3 * static_cast<Index>(st.general_handles.size()));
  for (size_t g = 0; g < st.general_handles.size(); ++g)
    cv.bg.segment<3>(3 * static_cast<Index>(g)) =
        Ft * targets.points.row(static_cast<Index>(st.general_handles[g])).transpose();
  cv.bg -= st.Ap * cv.up;
  cv.rhs_pinned = st.Hfp * cv.up;
  return cv;
}

constexpr double kNewtonForcing = 1e-6;
constexpr int kNewtonMaxCg = 500;

NewtonStep newton_step(Rounds& rounds, const LocalGlobalState& st, double energy, double* radius, int max_products,
                       const std::function<bool()>& cancel) {
  NewtonStep out;
  out.energy = energy;
  Eigen::VectorXd g;
  rounds.gradient(&g);
  const Index nf = g.size();
  const auto precondition = [&](const Eigen::VectorXd& r, Eigen::VectorXd* z) {
    Matrix<double> b = r;
    st.factor->solveInPlace(b, 1);
    *z = b.col(0);
  };
  // Steihaug's truncated CG in the K-norm ‖d‖²_K = dᵀKd (K the
  // preconditioner, so the first iterate is the local-global step), inside
  // the trust region ‖d‖_K ≤ radius; dᵀKd, dᵀKp and pᵀKp by recurrence.
  Eigen::VectorXd d = Eigen::VectorXd::Zero(nf), r = -g, z, p, Hp;
  precondition(r, &z);
  out.gradient_step_rms = rounds.vertex_rms(z);
  p = z;
  double rz = r.dot(z);
  const double r0 = std::sqrt(std::max(rz, 0.0));
  if (!(r0 > 0.0)) return out;
  if (!std::isfinite(*radius)) *radius = r0;  // the first step: as long as the local-global step
  double dKd = 0.0, dKp = 0.0, pKp = rz, model = 0.0;  // model: gᵀd + ½dᵀHd
  bool converged = false, boundary = false;
  for (int j = 0; j < max_products; ++j) {
    if (cancel && cancel()) {
      out.cancelled = true;
      return out;
    }
    rounds.hessian_vector(p, &Hp);
    ++out.cg;
    const double pHp = p.dot(Hp);
    const double alpha = rz / pHp;
    if (!(pHp > 0.0) || dKd + 2 * alpha * dKp + alpha * alpha * pKp >= *radius * *radius) {
      // To the boundary along p: τ ≥ 0 with ‖d + τp‖_K = radius.
      const double disc = dKp * dKp + pKp * (*radius * *radius - dKd);
      const double tau = (-dKp + std::sqrt(std::max(disc, 0.0))) / pKp;
      d += tau * p;
      model += -tau * rz + 0.5 * tau * tau * pHp;
      boundary = true;
      break;
    }
    d += alpha * p;
    model -= 0.5 * alpha * rz;
    r -= alpha * Hp;
    precondition(r, &z);
    const double rz_next = r.dot(z);
    const double beta = rz_next / rz;
    dKd += 2 * alpha * dKp + alpha * alpha * pKp;
    dKp = beta * (dKp + alpha * pKp);
    pKp = rz_next + beta * beta * pKp;
    p = z + beta * p;
    rz = rz_next;
    if (std::sqrt(std::max(rz, 0.0)) <= kNewtonForcing * r0) {
      converged = true;
      break;
    }
  }
  const double step_norm = std::sqrt(std::max(boundary ? *radius * *radius : dKd, 0.0));
  const double predicted = -model;
  if (!(predicted > 0.0) || !d.allFinite()) {
    *radius = 0.25 * step_norm;
    return out;
  }
  if (converged && !boundary) out.solved_rms = rounds.vertex_rms(d);
  const Eigen::VectorXd u0 = rounds.free_part();
  const Vertices X0 = rounds.X;
  rounds.set_free_part(u0 + d);
  const double next = rounds.local_step();
  const double ratio = (energy - next) / predicted;
  if (!(ratio > 1e-4) || !std::isfinite(next) || !rounds.X.allFinite()) {
    *radius = 0.25 * step_norm;
    rounds.set_free_part(u0);  // back, with its rotations
    rounds.local_step();
    return out;
  }
  if (ratio < 0.25) *radius = 0.25 * step_norm;
  else if (ratio > 0.75 && boundary) *radius *= 2.0;
  out.accepted = true;
  // Full: inside the region, the solve converged, and the model predicted
  // the energy's fall to 10 % (where it does not, the valley curves and
  // the step says little about the distance left).
  const double slack = 1e-12 * std::abs(energy);  // round-off of the energies near the minimiser
  out.full = converged && !boundary && std::abs((energy - next) - predicted) <= 0.1 * predicted + slack;
  out.energy = next;
  out.step_rms = rounds.vertex_rms(d);
  out.max_move = (rounds.X - X0).rowwise().norm().maxCoeff();
  return out;
}

// LocalGlobalArap::solve in the units-free frame: targets and `initial`
// (checked; empty: the rest pose) are in it, and so is what it returns.
ReferenceSummary run_rounds(const LocalGlobalState& st, const HandleTargets& targets, ReferenceSolution* out,
                            const Vertices& initial, const std::function<bool()>& cancel) {
  const PreparedModel& m = st.m;
  const bool classic = st.options.energy == ReferenceEnergy::ClassicArap;
  const Eigen::Matrix3d frame = classic ? Eigen::Matrix3d::Identity() : st.options.frame;
  const Eigen::Matrix3d Ft = frame.transpose();

  const Timer timer;
  ReferenceSummary summary;
  summary.energy_kind = st.options.energy;
  const ConstrainedValues cv = constrained_values(st, targets, frame);
  // Pose and rotations in the solve frame; those of the initial pose (the
  // identities at rest).
  Rounds rounds(st, classic, initial.size() > 0 ? Vertices(initial * frame) : m.V);  // rows: (Fᵀ v)ᵀ = vᵀF
  summary.initial_energy = classic || initial.size() > 0 ? rounds.local_step() : rounds.rest_rotations_energy();
  double energy = summary.initial_energy;
  summary.status = Status::Success;
  // The fixed-point iterate z = [vec V′; Q] (reference.h) and its image G(z).
  const Index nx = 3 * st.n;
  Eigen::VectorXd z(nx + rounds.Q.size()), gz(z.size()), za(z.size());
  const auto pack = [&](Eigen::VectorXd* v) {
    v->head(nx) = Eigen::Map<const Eigen::VectorXd>(rounds.X.data(), nx);
    v->tail(rounds.Q.size()) = rounds.Q;
  };
  const auto unpack = [&](const Eigen::VectorXd& v) {
    Eigen::Map<Eigen::VectorXd>(rounds.X.data(), nx) = v.head(nx);
    rounds.Q = v.tail(rounds.Q.size());
  };
  pack(&z);
  DistanceEstimate distance(nx, st.n, m.diagonal);
  constexpr int kHoldRounds = 16;
  int held_from = -1;  // the first round of the current run of estimates within distance_tolerance
  const bool accelerate = st.options.anderson_window > 0;
  // Newton steps after newton_after rounds: classic energy, no weighted
  // point rows (their Schur solve is not in the preconditioner).
  const bool newton_possible = classic && st.options.newton_after > 0 && st.Af.rows() == 0;
  bool newton_ready = false;
  double previous_newton_step = std::numeric_limits<double>::infinity();  // RMS of the last full Newton step
  double trust_radius = std::numeric_limits<double>::infinity();          // of the Newton steps, in the K-norm
  SafeguardedAnderson anderson;
  if (accelerate) anderson.reset(z.size(), AndersonOptions{st.options.anderson_window});
  // Records a round's (or Newton step's) energy and time; returns the
  // reference test (step and energy change) and the refine test (energy
  // change or fixed-point residual), on summary.last_step and
  // summary.fixed_point_residual as the caller set them.
  const auto end_round = [&](double next) {
    const double drop = std::abs(energy - next) / std::max(std::abs(next), 1e-300);
    energy = next;
    summary.round_energy.push_back(energy);
    summary.round_seconds.push_back(timer.seconds());
    const bool reference_test =
        summary.last_step <= st.options.step_tolerance * m.diagonal && drop <= st.options.energy_tolerance;
    const bool refine_test = st.options.tolerance > 0 &&
                             (drop <= st.options.tolerance || summary.fixed_point_residual <= st.options.tolerance);
    return std::pair<bool, bool>{reference_test, refine_test};
  };
  int it = 0;
  for (; it < st.options.max_iterations; ++it) {
    if (cancel && cancel()) {
      summary.cancelled = true;
      break;
    }
    if (newton_ready) {
      // max_iterations bounds the work: rounds and Hessian products (each a
      // solve with K, about a round) together.
      const int budget = st.options.max_iterations - it - summary.cg_iterations;
      if (budget <= 0) break;
      const NewtonStep step = newton_step(rounds, st, energy, &trust_radius, std::min(kNewtonMaxCg, budget), cancel);
      ++summary.newton_steps;
      summary.cg_iterations += step.cg;
      if (step.cancelled) {
        summary.cancelled = true;
        break;
      }
      double next = step.energy;
      summary.last_step = step.max_move;
      if (!step.accepted) {  // the plain round, which never raises the energy
        ++summary.newton_fallbacks;
        summary.last_step = rounds.global_step(cv);
        next = rounds.local_step();
      }
      summary.fixed_point_residual = step.gradient_step_rms * std::sqrt(static_cast<double>(st.n)) /
                                     std::max(rounds.X.norm(), std::numeric_limits<double>::min());
      // The distance left after full steps s_{k−1}, s_k of converged CG
      // solves that contract, ρ = |s_k| / |s_{k−1}| < 1: |s_k|·ρ / (1 − ρ)
      // (a linear rate; Newton's is faster). One step alone says nothing:
      // early in a flat valley CG's residual test is met by the fast modes
      // while the slow one is still far off.
      const double ratio = step.step_rms / previous_newton_step;
      summary.estimated_distance = step.full && std::isfinite(previous_newton_step) && ratio < 1.0
                                       ? step.step_rms * ratio / (1.0 - ratio) / m.diagonal
                                       : std::numeric_limits<double>::infinity();
      previous_newton_step = step.full ? step.step_rms : std::numeric_limits<double>::infinity();
      const auto [reference_test, refine_test] = end_round(next);
      const bool distance_test =
          st.options.distance_tolerance > 0 && summary.estimated_distance <= st.options.distance_tolerance;
      // The reference test (a move below 1e-10 of the diagonal, the energy
      // still to 1e-13) after a Newton solve that converged: the distance
      // left is about that solve's step, kept or refused at round-off.
      if (reference_test && !std::isfinite(summary.estimated_distance))
        summary.estimated_distance = step.solved_rms / m.diagonal;
      if (reference_test || refine_test || distance_test) {
        summary.converged = true;
        ++it;
        break;
      }
      continue;
    }
    if (newton_possible && it >= st.options.newton_after) {
      // The switch: one plain round, whose local step keeps the curvatures
      // and whose global step sets the control rows the Newton steps move.
      rounds.keep_curvature();
      newton_ready = true;
    }
    summary.last_step = rounds.global_step(cv);  // (V′, Q) = G(z)
    if (!rounds.X.allFinite() || !rounds.Q.allFinite()) {
      unpack(z);  // back to the last accepted pose
      rounds.local_step();
      summary.status = Status::NumericalFailure;
      summary.message = fmt::format("non-finite positions in round {}; returned the pose of round {}", it + 1, it);
      break;
    }
    pack(&gz);
    summary.fixed_point_residual = (gz - z).norm() / std::max(z.norm(), std::numeric_limits<double>::min());
    summary.estimated_distance = distance.update(z, gz);
    double next = 0.0;
    if (newton_ready) {  // the switching round: plain
      next = rounds.local_step();
      z.swap(gz);
    } else if (accelerate && anderson.history() > 0) {
      anderson.propose(z, gz, za);
      unpack(za);
      next = rounds.local_step();
      if (anderson.accept(std::isfinite(next) && rounds.X.allFinite() ? next : std::numeric_limits<double>::quiet_NaN(),
                         energy)) {
        z.swap(za);
      } else {  // the safeguard: the plain round, which never raises the energy
        unpack(gz);
        next = rounds.local_step();
        z.swap(gz);
      }
    } else {
      // The first steps after a start or a refusal are G(z): they fill the
      // history (the extrapolation of the step that makes it 1 is not tried).
      if (accelerate) anderson.propose(z, gz, za);
      next = rounds.local_step();
      z.swap(gz);
    }
    const auto [reference_test, refine_test] = end_round(next);
    // At the reference test the steps are at round-off, where the
    // estimate's Rayleigh quotient is noise: the distance left is about the
    // last move (as after a converged Newton solve above).
    if (reference_test) summary.estimated_distance = summary.last_step / m.diagonal;
    // The distance test holds once the estimate has stayed within the
    // tolerance for half the rounds so far (at least kHoldRounds): early on
    // the fast modes' progress can hide a slow one from the estimate.
    held_from = summary.estimated_distance <= st.options.distance_tolerance ? (held_from < 0 ? it : held_from) : -1;
    const bool distance_test = st.options.distance_tolerance > 0 && held_from >= 0 &&
                               it - held_from + 1 >= std::max(kHoldRounds, (it + 1) / 2);
    if (reference_test || refine_test || distance_test) {
      summary.converged = true;
      ++it;
      break;
    }
  }
  summary.iterations = it;
  summary.rejected_steps = anderson.rejected();
  summary.solve_seconds = timer.seconds();
  // Back to the world frame.
  out->V = rounds.X * Ft;  // rows: (F x)ᵀ = xᵀFᵀ
  out->Q = rounds.Q;
  out->rotations = rounds.R;
  if (!classic) detail_reference::rotations_to_world(frame, &out->rotations);
  summary.energy = energy;  // of the returned (V′, R) or (V′, Q, S)
  summary.handle_residual = handle_residual(st.frame_targets, st.handles, targets, out->V);
  if (summary.status == Status::Success && summary.cancelled) {
    summary.message = fmt::format("cancelled after {} rounds", it);
  } else if (summary.status == Status::Success && !summary.converged) {
    summary.message = fmt::format("iteration limit ({}) reached; last step {:.3e} of the bounding-box diagonal",
                                  st.options.max_iterations, summary.last_step / m.diagonal);
  } else if (summary.status == Status::Success) {
    summary.message = fmt::format("converged in {} rounds", it);
  }
  return summary;
}

}  // namespace qpreduce::deform::detail_reference
