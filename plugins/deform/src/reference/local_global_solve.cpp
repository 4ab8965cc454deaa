// LocalGlobalArap's solve (local_global_rounds.h): the constraint values,
// the Newton steps on the classic energy, and the rounds with Anderson
// acceleration (SafeguardedAnderson) and the stop tests.
#include "local_global_rounds.h"

#include <fmt/format.h>

namespace qpreduce::deform::detail {

ConstrainedValues constrained_values(const LocalGlobalState& st, const HandleTargets& targets,
                                     const Eigen::Matrix3d& frame) {
  const PreparedModel& m = st.m;
  const Eigen::Matrix3d Ft = frame.transpose();
  ConstrainedValues cv;
  cv.up.resize(static_cast<Index>(st.pinned_rows.size()));
  {
    Eigen::VectorXd u = Eigen::VectorXd::Zero(st.nu);
    for (const auto& pt : detail::patch_targets(m, st.handles, targets, frame)) {
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

namespace {

// Steihaug's truncated CG for the Newton step d (H·d = −g), the state the
// step's acceptance reads.
struct TruncatedCg {
  Eigen::VectorXd d;
  double dKd = 0.0;    // ‖d‖²_K
  double model = 0.0;  // gᵀd + ½dᵀHd
  bool converged = false, boundary = false;
};

// Steihaug's truncated CG in the K-norm ‖d‖²_K = dᵀKd (K the
// preconditioner, so the first iterate is the local-global step), inside
// the trust region ‖d‖_K ≤ radius; dᵀKd, dᵀKp and pᵀKp by recurrence.
// False when there is no step to take (a zero gradient, or a cancel:
// out->cancelled); out->cg and out->gradient_step_rms are set either way.
bool truncated_cg(Rounds& rounds, const LocalGlobalState& st, double* radius, int max_products,
                  const std::function<bool()>& cancel, NewtonStep* out, TruncatedCg* cg) {
  Eigen::VectorXd g;
  rounds.gradient(&g);
  const Index nf = g.size();
  Matrix<double> b(nf, 1);
  const auto precondition = [&](const Eigen::VectorXd& r, Eigen::VectorXd* z) {
    b.col(0) = r;
    st.factor->solveInPlace(b, 1);
    *z = b.col(0);
  };
  Eigen::VectorXd& d = cg->d;
  d = Eigen::VectorXd::Zero(nf);
  Eigen::VectorXd r = -g, z, p, Hp;
  precondition(r, &z);
  out->gradient_step_rms = rounds.vertex_rms(z);
  p = z;
  double rz = r.dot(z);
  const double r0 = std::sqrt(std::max(rz, 0.0));
  if (!(r0 > 0.0)) return false;
  if (!std::isfinite(*radius)) *radius = r0;  // the first step: as long as the local-global step
  double dKd = 0.0, dKp = 0.0, pKp = rz, model = 0.0;
  for (int j = 0; j < max_products; ++j) {
    if (cancel && cancel()) {
      out->cancelled = true;
      return false;
    }
    rounds.hessian_vector(p, &Hp);
    ++out->cg;
    const double pHp = p.dot(Hp);
    const double alpha = rz / pHp;
    if (!(pHp > 0.0) || dKd + 2 * alpha * dKp + alpha * alpha * pKp >= *radius * *radius) {
      // To the boundary along p: τ ≥ 0 with ‖d + τp‖_K = radius.
      const double disc = dKp * dKp + pKp * (*radius * *radius - dKd);
      const double tau = (-dKp + std::sqrt(std::max(disc, 0.0))) / pKp;
      d += tau * p;
      model += -tau * rz + 0.5 * tau * tau * pHp;
      cg->boundary = true;
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
      cg->converged = true;
      break;
    }
  }
  cg->dKd = dKd;
  cg->model = model;
  return true;
}

}  // namespace

NewtonStep newton_step(Rounds& rounds, const LocalGlobalState& st, double energy, double* radius, int max_products,
                       const std::function<bool()>& cancel) {
  NewtonStep out;
  out.energy = energy;
  TruncatedCg cg;
  if (!truncated_cg(rounds, st, radius, max_products, cancel, &out, &cg)) return out;
  const Eigen::VectorXd& d = cg.d;
  const bool converged = cg.converged, boundary = cg.boundary;
  const double dKd = cg.dKd, model = cg.model;
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

namespace {

constexpr int kHoldRounds = 16;
// The safeguard keeps an extrapolation whose energy is within this of the
// accepted one, relative: energies that close are equal to their round-off
// (a sum over the elements), and which of them came out lower is noise that
// would pick the step by the last bits of the input (its units, its place).
constexpr double kEnergyRoundOff = 1e-13;

// One run of run_rounds: the pose and rotations (Rounds), the fixed-point
// iterate z = [vec V′; Q] (reference.h), its image G(z) and an
// extrapolation, Anderson's history, the Newton steps' state and the stop
// tests' memory, in the solve frame.
class RoundLoop {
 public:
  RoundLoop(const LocalGlobalState& st, const HandleTargets& targets, const Vertices& initial, bool classic,
            const Eigen::Matrix3d& frame)
      : st_(st), m_(st.m), cv_(constrained_values(st, targets, frame)),
        // Pose and rotations in the solve frame; those of the initial pose
        // (the identities at rest).
        rounds_(st, classic, initial.size() > 0 ? Vertices(initial * frame) : st.m.V),  // rows: (Fᵀ v)ᵀ = vᵀF
        nx_(3 * st.n), distance_(nx_, st.n, st.m.diagonal), accelerate_(st.options.anderson_window > 0),
        // Newton steps after newton_after rounds: classic energy, no weighted
        // point rows (their Schur solve is not in the preconditioner).
        newton_possible_(classic && st.options.newton_after > 0 && st.Af.rows() == 0) {
    summary.energy_kind = st.options.energy;
    summary.initial_energy = classic || initial.size() > 0 ? rounds_.local_step() : rounds_.rest_rotations_energy();
    energy_ = summary.initial_energy;
    summary.status = Status::Success;
    z_.resize(nx_ + rounds_.Q.size());
    gz_.resize(z_.size());
    za_.resize(z_.size());
    pack(&z_);
    if (accelerate_) anderson_.reset(z_.size(), AndersonOptions{st.options.anderson_window});
  }

  // The rounds until a stop test holds, the cap, a cancel or a failure;
  // returns the number of rounds (and Newton steps) run.
  int run(const std::function<bool()>& cancel) {
    int it = 0;
    for (; it < st_.options.max_iterations; ++it) {
      if (cancel && cancel()) {
        summary.cancelled = true;
        break;
      }
      if (newton_ready_) {
        if (newton_round(&it, cancel)) break;
        continue;
      }
      if (plain_round(&it)) break;
    }
    summary.iterations = it;
    summary.rejected_steps = anderson_.rejected();
    summary.solve_seconds = timer_.seconds();
    return it;
  }

  const Rounds& rounds() const { return rounds_; }
  double energy() const { return energy_; }

  ReferenceSummary summary;

 private:
  void pack(Eigen::VectorXd* v) const {
    v->head(nx_) = Eigen::Map<const Eigen::VectorXd>(rounds_.X.data(), nx_);
    v->tail(rounds_.Q.size()) = rounds_.Q;
  }
  void unpack(const Eigen::VectorXd& v) {
    Eigen::Map<Eigen::VectorXd>(rounds_.X.data(), nx_) = v.head(nx_);
    rounds_.Q = v.tail(rounds_.Q.size());
  }

  // Records a round's (or Newton step's) energy and time; returns the
  // reference test (step and energy change) and the refine test (energy
  // change or fixed-point residual), on summary.last_step and
  // summary.fixed_point_residual as the caller set them.
  std::pair<bool, bool> end_round(double next) {
    const double drop = std::abs(energy_ - next) / std::max(std::abs(next), 1e-300);
    energy_ = next;
    summary.round_energy.push_back(energy_);
    summary.round_seconds.push_back(timer_.seconds());
    const bool reference_test =
        summary.last_step <= st_.options.step_tolerance * m_.diagonal && drop <= st_.options.energy_tolerance;
    const bool refine_test = st_.options.tolerance > 0 &&
                             (drop <= st_.options.tolerance || summary.fixed_point_residual <= st_.options.tolerance);
    return {reference_test, refine_test};
  }

  // A Newton step after the switch; true when the run ends (*it counts a
  // step that converged).
  bool newton_round(int* it, const std::function<bool()>& cancel) {
    // max_iterations bounds the work: rounds and Hessian products (each a
    // solve with K, about a round) together.
    const int budget = st_.options.max_iterations - *it - summary.cg_iterations;
    if (budget <= 0) return true;
    const NewtonStep step = newton_step(rounds_, st_, energy_, &trust_radius_, std::min(kNewtonMaxCg, budget), cancel);
    ++summary.newton_steps;
    summary.cg_iterations += step.cg;
    if (step.cancelled) {
      summary.cancelled = true;
      return true;
    }
    double next = step.energy;
    summary.last_step = step.max_move;
    if (!step.accepted) {  // the plain round, which never raises the energy
      ++summary.newton_fallbacks;
      summary.last_step = rounds_.global_step(cv_);
      next = rounds_.local_step();
    }
    summary.fixed_point_residual = step.gradient_step_rms * std::sqrt(static_cast<double>(st_.n)) /
                                   std::max(rounds_.X.norm(), std::numeric_limits<double>::min());
    // The distance left after full steps s_{k−1}, s_k of converged CG
    // solves that contract, ρ = |s_k| / |s_{k−1}| < 1: |s_k|·ρ / (1 − ρ)
    // (a linear rate; Newton's is faster). One step alone says nothing:
    // early in a flat valley CG's residual test is met by the fast modes
    // while the slow one is still far off.
    const double ratio = step.step_rms / previous_newton_step_;
    summary.estimated_distance = step.full && std::isfinite(previous_newton_step_) && ratio < 1.0
                                     ? step.step_rms * ratio / (1.0 - ratio) / m_.diagonal
                                     : std::numeric_limits<double>::infinity();
    previous_newton_step_ = step.full ? step.step_rms : std::numeric_limits<double>::infinity();
    const auto [reference_test, refine_test] = end_round(next);
    const bool distance_test =
        st_.options.distance_tolerance > 0 && summary.estimated_distance <= st_.options.distance_tolerance;
    // The reference test (a move below 1e-10 of the diagonal, the energy
    // still to 1e-13) after a Newton solve that converged: the distance
    // left is about that solve's step, kept or refused at round-off.
    if (reference_test && !std::isfinite(summary.estimated_distance))
      summary.estimated_distance = step.solved_rms / m_.diagonal;
    if (reference_test || refine_test || distance_test) {
      summary.converged = true;
      ++*it;
      return true;
    }
    return false;
  }

  // A local-global round, plain or accelerated; true when the run ends (*it
  // counts a round that converged).
  bool plain_round(int* it) {
    if (newton_possible_ && *it >= st_.options.newton_after) {
      // The switch: one plain round, whose local step keeps the curvatures
      // and whose global step sets the control rows the Newton steps move.
      rounds_.keep_curvature();
      newton_ready_ = true;
    }
    summary.last_step = rounds_.global_step(cv_);  // (V′, Q) = G(z)
    if (!rounds_.X.allFinite() || !rounds_.Q.allFinite()) {
      unpack(z_);  // back to the last accepted pose
      rounds_.local_step();
      summary.status = Status::NumericalFailure;
      summary.message = fmt::format("non-finite positions in round {}; returned the pose of round {}", *it + 1, *it);
      return true;
    }
    pack(&gz_);
    summary.fixed_point_residual = (gz_ - z_).norm() / std::max(z_.norm(), std::numeric_limits<double>::min());
    summary.estimated_distance = distance_.update(z_, gz_);
    const double next = next_pose();
    const auto [reference_test, refine_test] = end_round(next);
    // At the reference test the steps are at round-off, where the
    // estimate's Rayleigh quotient is noise: the distance left is about the
    // last move (as after a converged Newton solve above).
    if (reference_test) summary.estimated_distance = summary.last_step / m_.diagonal;
    // The distance test holds once the estimate has stayed within the
    // tolerance for half the rounds so far (at least kHoldRounds): early on
    // the fast modes' progress can hide a slow one from the estimate.
    held_from_ =
        summary.estimated_distance <= st_.options.distance_tolerance ? (held_from_ < 0 ? *it : held_from_) : -1;
    const bool distance_test = st_.options.distance_tolerance > 0 && held_from_ >= 0 &&
                               *it - held_from_ + 1 >= std::max(kHoldRounds, (*it + 1) / 2);
    if (reference_test || refine_test || distance_test) {
      summary.converged = true;
      ++*it;
      return true;
    }
    return false;
  }

  // From G(z) in gz_: the next accepted z (G(z), or Anderson's extrapolation
  // when the safeguard keeps it) and its local step; returns its energy.
  double next_pose() {
    double next = 0.0;
    if (newton_ready_) {  // the switching round: plain
      next = rounds_.local_step();
      z_.swap(gz_);
    } else if (accelerate_ && anderson_.history() > 0) {
      anderson_.propose(z_, gz_, za_);
      unpack(za_);
      next = rounds_.local_step();
      if (anderson_.accept(
              std::isfinite(next) && rounds_.X.allFinite() ? next : std::numeric_limits<double>::quiet_NaN(),
              energy_, kEnergyRoundOff * std::abs(energy_))) {
        z_.swap(za_);
      } else {  // the safeguard: the plain round, which never raises the energy
        unpack(gz_);
        next = rounds_.local_step();
        z_.swap(gz_);
      }
    } else {
      // The first steps after a start or a refusal are G(z): they fill the
      // history (the extrapolation of the step that makes it 1 is not tried).
      if (accelerate_) anderson_.propose(z_, gz_, za_);
      next = rounds_.local_step();
      z_.swap(gz_);
    }
    return next;
  }

  const Timer timer_;
  const LocalGlobalState& st_;
  const PreparedModel& m_;
  const ConstrainedValues cv_;
  Rounds rounds_;
  const Index nx_;
  DistanceEstimate distance_;
  const bool accelerate_, newton_possible_;
  Eigen::VectorXd z_, gz_, za_;
  double energy_ = 0.0;
  int held_from_ = -1;  // the first round of the current run of estimates within distance_tolerance
  bool newton_ready_ = false;
  double previous_newton_step_ = std::numeric_limits<double>::infinity();  // RMS of the last full Newton step
  double trust_radius_ = std::numeric_limits<double>::infinity();          // of the Newton steps, in the K-norm
  SafeguardedAnderson anderson_;
};

}  // namespace

// LocalGlobalArap::solve in the units-free frame: targets and `initial`
// (checked; empty: the rest pose) are in it, and so is what it returns.
ReferenceSummary run_rounds(const LocalGlobalState& st, const HandleTargets& targets, ReferenceSolution* out,
                            const Vertices& initial, const std::function<bool()>& cancel) {
  const bool classic = st.options.energy == ReferenceEnergy::ClassicArap;
  const Eigen::Matrix3d frame = classic ? Eigen::Matrix3d::Identity() : st.options.frame;
  RoundLoop loop(st, targets, initial, classic, frame);
  const int it = loop.run(cancel);
  ReferenceSummary summary = std::move(loop.summary);
  // Back to the world frame.
  const Rounds& rounds = loop.rounds();
  out->V = rounds.X * frame.transpose();  // rows: (F x)ᵀ = xᵀFᵀ
  out->Q = rounds.Q;
  out->rotations = rounds.R;
  if (!classic) detail::rotations_to_world(frame, &out->rotations);
  summary.energy = loop.energy();  // of the returned (V′, R) or (V′, Q, S)
  summary.handle_residual = handle_residual(st.frame_targets, st.handles, targets, out->V);
  if (summary.status == Status::Success && summary.cancelled) {
    summary.message = fmt::format("cancelled after {} rounds", it);
  } else if (summary.status == Status::Success && !summary.converged) {
    summary.message = fmt::format("iteration limit ({}) reached; last step {:.3e} of the bounding-box diagonal",
                                  st.options.max_iterations, summary.last_step / st.m.diagonal);
  } else if (summary.status == Status::Success) {
    summary.message = fmt::format("converged in {} rounds", it);
  }
  return summary;
}

}  // namespace qpreduce::deform::detail
