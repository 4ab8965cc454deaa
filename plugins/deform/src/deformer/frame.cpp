// Deformer::frame (paper Section 3.2 and the appendix's global rotation
// adaptation): the handle targets in the frame of r₀, k rounds of Phase 1
// and Phase 2 warm-started from the last frame, and the reconstruction
// V′ = r₀·(P·[N UD]·[X; S_local]); reset_pose and the round threads.
#include "qpreduce/deform/deformer/deformer.h"
#include "qpreduce/deform/mesh/mesh_check.h"  // kMaxReach

#include "state.h"

#include <qpreduce/anderson.h>
#include <qpreduce/point_reconstruction.h>
#include <qpreduce/checks.h>
#include <qpreduce/util/timer.h>

#include <Eigen/LU>

#include <algorithm>
#include <cmath>
#include <limits>

#include <fmt/format.h>

namespace qpreduce::deform {
namespace {

using detail::Model;
using detail::OnSite;
using detail::Pose;
using detail::Workspace;

// Sizes and finiteness of the targets, and how far they reach from the rest
// pose in its frame (reach_in_frame; beyond kMaxReach diagonals they would
// overflow in the energy: the rule and the words of qpr's scenario check);
// a Rigid patch's transform must be a rotation. Throws std::invalid_argument.
void check_targets(const Model& model, const Handles& handles, const HandleTargets& targets) {
  check_size("Deformer::frame: target points", static_cast<Index>(handles.points.size()), targets.points.rows());
  check_size("Deformer::frame: patch transforms", static_cast<Index>(handles.patches.size()),
             static_cast<Index>(targets.patch_transforms.size()));
  if (targets.points.size() > 0) check_finite("Deformer::frame: target points", targets.points);
  for (const auto& T : targets.patch_transforms) check_finite("Deformer::frame: patch transform", T);
  const double reach = reach_in_frame(targets, model.frame, handles);  // no allocation on a frame's path
  if (!(reach <= kMaxReach)) {
    std::string where;
    reach_in_frame(targets, model.frame, handles, &where);
    throw std::invalid_argument("Deformer::frame: " + reach_message(where, reach));
  }
  for (size_t i = 0; i < targets.patch_transforms.size(); ++i) {
    const auto& T = targets.patch_transforms[i];
    const Index p = handles.patches[i];
    if (model.patch_types[p] == PatchType::Rigid) {
      const Eigen::Matrix3d A = T.leftCols<3>();
      const double off = (A.transpose() * A - Eigen::Matrix3d::Identity()).norm();
      if (off > 1e-6 || A.determinant() <= 0) {
        throw std::invalid_argument(fmt::format(
            "Deformer::frame: patch {} is Rigid but its transform is not a rotation (‖AᵀA − I‖ = {:.3e}, det = {:.3e})",
            p, off, A.determinant()));
      }
    }
  }
}

// Global rotation adaptation: r₀ from the area-weighted mean of the cluster
// rotations (identity when disabled).
Eigen::Matrix3d global_rotation_of(const Model& model, const Eigen::VectorXd& S, bool enabled) {
  if (!enabled) return Eigen::Matrix3d::Identity();
  Eigen::Matrix3d G = Eigen::Matrix3d::Zero();
  for (Index i = 0; i < model.d; ++i) G += model.cluster_measure(i) * Eigen::Map<const Eigen::Matrix3d>(S.data() + 9 * i);
  return fit_rotation(G);
}

// b in the normalised frame (Deformer::Normalization: x̂ = (x − c)/σ) rotated
// by r₀ᵀ: the point targets, the Fixed patches at rest, then the prescribed
// patches' transforms, x ↦ A·x + t becoming x̂ ↦ A·x̂ + (A·c + t − c)/σ (the
// ties' rows stay zero).
void fill_targets(const Model& model, const HandleTargets& targets, const Eigen::Matrix3d& r0t, Eigen::VectorXd* b) {
  const Eigen::Vector3d& c = model.frame.centre;
  const double inv_scale = 1.0 / model.frame.scale;
  Index row = 0;
  for (Index h = 0; h < targets.points.rows(); ++h) {
    b->segment<3>(row) = r0t * ((targets.points.row(h).transpose() - c) * inv_scale);
    row += 3;
  }
  auto put_patch = [&](const Eigen::Matrix<double, 3, 4>& T) {
    const Eigen::Matrix3d A = r0t * T.leftCols<3>();
    const Eigen::Vector3d tr = r0t * ((T.leftCols<3>() * c + T.col(3) - c) * inv_scale);
    for (int a = 0; a < 3; ++a)
      for (int c = 0; c < 3; ++c) (*b)(row + 3 * a + c) = A(a, c);
    b->segment<3>(row + 9) = tr;
    row += 12;
  };
  const Eigen::Matrix<double, 3, 4> identity = Eigen::Matrix<double, 3, 4>::Identity();
  for (size_t i = 0; i < model.fixed_patches.size(); ++i) put_patch(identity);
  for (const auto& T : targets.patch_transforms) put_patch(T);
}

// Per cluster: to = R·from (3 × 3 blocks of 9d vectors).
void rotate_clusters(Index d, const Eigen::Matrix3d& R, const Eigen::VectorXd& from, Eigen::VectorXd* to) {
  for (Index i = 0; i < d; ++i) {
    Eigen::Map<Eigen::Matrix3d>(to->data() + 9 * i) = R * Eigen::Map<const Eigen::Matrix3d>(from.data() + 9 * i);
  }
}

// b and S_local in the frame of r₀ (targets and cluster rotations turned by
// r₀ᵀ) into work->b, work->s_local.
void into_frame(const Model& model, const OnSite& onsite, const HandleTargets& targets, const Eigen::Matrix3d& r0,
                const Eigen::VectorXd& S, Workspace* work) {
  const Eigen::Matrix3d r0t = r0.transpose();
  if (onsite.target_projection.size() == 0) {
    fill_targets(model, targets, r0t, &work->b);
  } else {  // a dependent set: its targets projected onto its independent rows
    fill_targets(model, targets, r0t, &work->b_targets);
    work->b.noalias() = onsite.target_projection * work->b_targets;
  }
  rotate_clusters(model.d, r0t, S, &work->s_local);
}

// Into the frame of the refitted r₀ (`fitted`; pose.r0, work.b,
// work.s_local), keeping b and S_local in the last frame's r₀ and the warm
// start's E′ there (returned, with its round-off slack; NaN when the rounds
// are not `judged` by an energy, without energy terms, or when r₀ does not
// change).
double refit_frame(const Model& model, const HandleTargets& targets, const Eigen::Matrix3d& fitted, bool judged,
                   OnSite* onsite, Pose* pose, Workspace* work, double* slack) {
  if (fitted == pose->r0 || !judged) {
    pose->r0 = fitted;
    into_frame(model, *onsite, targets, pose->r0, pose->S, work);
    return std::numeric_limits<double>::quiet_NaN();
  }
  into_frame(model, *onsite, targets, pose->r0, pose->S, work);
  const double kept = onsite->alternation.energy(*model.projection, work->b, work->s_local, slack);
  if (!std::isnan(kept)) {
    work->b_kept = work->b;  // allocates on the first frame only
    work->s_kept = work->s_local;
  }
  pose->r0 = fitted;
  into_frame(model, *onsite, targets, pose->r0, pose->S, work);
  return kept;
}

// The first frame after set_handles runs to DeformerOptions::
// cold_start_tolerance, within cold_start_rounds rounds (second-order steps
// count kRoundsPerSecondOrderStep each), without a time budget.
void cold_start(const detail::Settings& settings, bool second_order, AlternationSettings* opts) {
  const int cap = second_order ? std::max(1, settings.cold_start_rounds / DeformerOptions::kRoundsPerSecondOrderStep)
                               : settings.cold_start_rounds;
  opts->iterations = std::max(opts->iterations, cap);
  const double tol = settings.cold_start_tolerance;
  opts->tolerance = opts->tolerance > 0.0 ? std::min(opts->tolerance, tol) : tol;
  opts->time_budget = 0.0;
}

// E′ and its subspace depend on r₀ (the corrections q_k = q0·I + [ω]× of
// Eq. 9 are linear about its frame: that is why r₀ is refitted), so the
// rotations S are another pose in the refitted frame. Refitted from the S
// of rounds stopped short of their fixed point, r₀ can turn so far in one
// frame that the pose's E′ rises by orders of magnitude (docs/robustness.md,
// "Soak"): when this frame's rounds (`first`, after `spent` seconds) end
// above the warm start's E′ in the last r₀, they run again there, in what
// is left of the budget and the round cap (at least one round). Returns
// their results, with the first run's rounds and rejections counted in.
AlternationResults rerun_in_last_rotation(const Model& model, AlternationSettings opts, double spent,
                                          const AlternationResults& first, OnSite* onsite, Pose* pose,
                                          Workspace* work) {
  pose->r0 = work->r0_before;
  pose->x = work->x_before;
  work->b = work->b_kept;
  work->s_local = work->s_kept;
  if (opts.time_budget > 0.0) opts.time_budget = std::max(opts.time_budget - spent, 1e-12);
  opts.iterations = std::max(1, opts.iterations - first.iterations);
  AlternationResults as = onsite->alternation.solve(*model.projection, work->b, opts, pose->x, work->s_local);
  as.iterations += first.iterations;
  as.rejected += first.rejected;
  return as;
}

// The rounds' part of a frame's summary (S_local after them: the residual's scale).
void record_rounds(const AlternationResults& as, const Eigen::VectorXd& s_local, double energy_unit,
                   FrameSummary* summary) {
  summary->iterations = as.iterations;
  summary->stop = as.stop;
  summary->last_change = as.last_change;
  summary->fixed_point_residual = as.last_change / std::max(s_local.norm(), 1e-300);
  summary->model_energy = as.energy * energy_unit;
  summary->rejected_steps = as.rejected;
  summary->second_order = as.second_order;
}

// V′ = c + σ·r₀·(B·w) of the last frame, from the float basis or the
// double one (DeformerOptions::double_basis).
template <typename Out>
void reconstruct(const detail::Model& model, const detail::Pose& pose, Out out) {
  if (model.double_basis) {
    reconstruct_points(model.basis_double, pose.wd, pose.r0, out, model.frame.scale, model.frame.centre);
  } else {
    reconstruct_points(model.basis, pose.wf, pose.r0.cast<float>(), out, model.frame.scale, model.frame.centre);
  }
}

}  // namespace

FrameSummary Deformer::frame(const HandleTargets& targets, Vertices* out) {
  State& st = *state_;
  const Model& model = st.model;
  const OnSite& onsite = st.onsite;
  Pose& pose = st.pose;
  Workspace& work = st.work;
  if (!st.ready || !onsite.alternation.ready()) {
    throw std::invalid_argument("Deformer::frame: call precompute and set_handles first");
  }
  check_targets(model, onsite.handles, targets);
  const Timer total;
  FrameSummary summary;

  // Solve in the frame rotated by r₀ᵀ.
  work.x_before = pose.x;  // same size every frame: no allocation
  work.r0_before = pose.r0;
  AlternationSettings opts = st.settings.alternating;
  const bool second_order = onsite.alternation.second_order(*model.projection, opts);
  if (!onsite.warm && st.settings.cold_start_rounds > 0) {
    cold_start(st.settings, second_order, &opts);
    summary.cold_start = true;
  }
  st.onsite.warm = true;
  if (!onsite.plain_reason.empty()) opts.anderson_window = 0;  // set_handles said why
  // Plain rounds judge no energy (FrameSummary::model_energy NaN): their
  // refit is taken as it comes.
  const bool judged = onsite.alternation.reports_energy(*model.projection, opts);
  double slack = 0.0;
  const double kept = refit_frame(model, targets, global_rotation_of(model, pose.S, st.settings.global_rotation),
                                  judged, &st.onsite, &pose, &work, &slack);
  Timer t;  // the rounds (FrameSummary::solve_seconds): the refit's product is in total_seconds
  AlternationResults as = st.onsite.alternation.solve(*model.projection, work.b, opts, pose.x, work.s_local);
  if (!std::isnan(kept) && !(as.energy <= kept + slack)) {
    as = rerun_in_last_rotation(model, opts, t.seconds(), as, &st.onsite, &pose, &work);
    summary.rotation_kept = true;
  }
  record_rounds(as, work.s_local, model.energy_unit, &summary);
  if (!onsite.plain_reason.empty() && st.settings.alternating.anderson_window > 0) {
    summary.message = "plain rounds: " + onsite.plain_reason + " (no acceleration)";
  }
  summary.status = as.status;
  if (!pose.x.allFinite() || !work.s_local.allFinite()) {
    // Keep the last good pose (S is still untouched): no NaN reaches the
    // reconstruction, the caller's vertices or the next frame's warm start.
    summary.status = Status::NumericalFailure;
    summary.message =
        "the alternating rounds produced NaN or infinite reduced coordinates; the pose is left as after the last "
        "good frame";
    pose.x = work.x_before;
    pose.r0 = work.r0_before;
    summary.solve_seconds = t.seconds();
    summary.total_seconds = total.seconds();
    return summary;
  }
  rotate_clusters(model.d, pose.r0, work.s_local, &pose.S);
  summary.solve_seconds = t.seconds();

  // Reconstruction V′ = r₀·(P·[N UD]·[X; S_local]), parallel over vertices.
  t.reset();
  pose.wf.head(model.nx) = pose.x.cast<float>();
  pose.wf.tail(9 * model.d) = work.s_local.cast<float>();
  if (model.double_basis) pose.wd << pose.x, work.s_local;
  if (out == nullptr) {  // the caller reconstructs (reconstruction_basis, reduced_coordinates)
    summary.total_seconds = total.seconds();
    return summary;
  }
  reconstruct(model, pose, out);
  summary.reconstruct_seconds = t.seconds();
  summary.total_seconds = total.seconds();
  return summary;
}

FrameSummary Deformer::frame(const HandleTargets& targets, Eigen::Map<Vertices> out) {
  if (state_->ready) check_size("Deformer::frame: out rows (vertices)", state_->model.n, out.rows());
  FrameSummary summary = frame(targets, nullptr);
  const Timer t;
  const Model& model = state_->model;
  reconstruct(model, state_->pose, out);
  summary.reconstruct_seconds = t.seconds();
  summary.total_seconds += summary.reconstruct_seconds;
  return summary;
}

void Deformer::reset_pose() {
  Pose& pose = state_->pose;
  for (Index i = 0; i < state_->model.d; ++i) Eigen::Map<Eigen::Matrix3d>(pose.S.data() + 9 * i).setIdentity();
  pose.r0.setIdentity();
  pose.x.setZero();
  state_->onsite.warm = false;  // the next frame starts from rest: a cold start
}

void Deformer::set_round_threads(int threads) {
  if (threads < 0) {
    throw std::invalid_argument(fmt::format("Deformer::set_round_threads: threads must be ≥ 0, got {}", threads));
  }
  state_->settings.alternating.threads = threads;
}

void Deformer::set_rounds(int iterations, double tolerance, double time_budget) {
  AlternationSettings rounds = state_->settings.alternating;
  rounds.iterations = iterations;
  rounds.tolerance = tolerance;
  rounds.time_budget = time_budget;
  std::string why;
  if (!rounds.is_valid(&why)) throw std::invalid_argument("Deformer::set_rounds: " + why);
  state_->settings.alternating = rounds;
}

void Deformer::set_anderson_window(int window) {
  if (window < 0 || window > AndersonAcceleration::kMaxWindow) {
    throw std::invalid_argument(fmt::format("Deformer::set_anderson_window: the window must be in [0, {}], got {}",
                                            AndersonAcceleration::kMaxWindow, window));
  }
  State& st = *state_;
  if (window > 0 && st.inputs.options.rotation_fit != ClusterRotationFit::Exact) {
    throw std::invalid_argument(
        "Deformer::set_anderson_window: accelerated rounds need rotation_fit Exact (this model was precomputed "
        "with the paper's Eq. 19 step)");
  }
  // set_handles formed the energy terms (or said why not: plain_reason).
  st.settings.alternating.anderson_window = window;
}

}  // namespace qpreduce::deform
