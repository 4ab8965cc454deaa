// Plain rounds, serial or on threads over block ranges (fused_steps.h).
#include "fused_steps.h"

#include "round_product.h"

#include <omp.h>

#include <algorithm>

namespace qpreduce::detail {

AlternationResults run_parallel(const FusedModel& M, FusedWorkspace& W, InputProjection<double>& projection,
                                const AlternationSettings& options, const detail::StopTest& stop, Index threads,
                                Index block, Eigen::Ref<Vector<double>> y) {
  const Index q = M.q(), blocks = q / block, mu = M.rounds().scratch_size();
  const bool use_float = options.float_products;
  W.y2.resize(q, 2);
  W.y2.col(0) = y;
  // Float rounds: whether the first round moves the reference (every thread
  // then takes the same decision after each barrier, from the same sums).
  const bool first_at_reference = use_float && !near_reference(W, y.data(), q, kNoChange);
  if (use_float) {
    W.yf2.resize(q, 2);
    W.yf2.col(0) = W.yf;
  }
  // Per-thread Σ‖Δy_j‖², ‖y_j‖² and ‖y_j − y_r,j‖², by round parity: read
  // after the round's barrier, next written two rounds later (after the next barrier).
  constexpr int kMaxThreads = 64;
  threads = std::min<Index>(threads, kMaxThreads);
  double change2[2][kMaxThreads] = {}, norm2[2][kMaxThreads] = {}, drift2[2][kMaxThreads] = {};
  // Thread 0's reading of the budget, by round parity like the sums, so that
  // every thread takes the same decision.
  bool spent[2] = {false, false};
  W.scratch_threads.resize(mu, threads);  // these allocate on the first call only
  W.scratch_f_threads.resize(mu, threads);
  AlternationResults summary;
#pragma omp parallel num_threads(static_cast<int>(threads))
  {
    const Index t = omp_get_thread_num(), nt = omp_get_num_threads();
    const Index r0 = block * (blocks * t / nt), r1 = block * (blocks * (t + 1) / nt), rows = r1 - r0;
    double* scratch = W.scratch_threads.col(t).data();
    float* scratch_f = W.scratch_f_threads.col(t).data();
    bool at_reference = first_at_reference;
    for (int it = 0; it < options.iterations; ++it) {
      const int cur = it % 2, next = 1 - cur;
      if (!use_float) {
        double_product(M, W, W.y2.col(cur).data(), r0, r1, scratch);
      } else if (at_reference) {  // this thread's rows of y_r: no other thread reads them this round
        reference_product(M, W, W.y2.col(cur).data(), r0, r1, scratch);
        W.y_ref.segment(r0, rows) = W.y2.col(cur).segment(r0, rows);
      } else {
        difference_product(M, W, W.yf2.col(cur).data(), r0, r1, scratch_f);
      }
      change2[cur][t] = projection.project_blocks(W.g, y, r0 / block, r1 / block);
      norm2[cur][t] = static_cast<double>(y.segment(r0, rows).squaredNorm());
      W.y2.col(next).segment(r0, rows) = y.segment(r0, rows);
      if (use_float) {
        drift2[cur][t] = (y.segment(r0, rows) - W.y_ref.segment(r0, rows)).squaredNorm();
        W.yf2.col(next).segment(r0, rows) = (y.segment(r0, rows) - W.y_ref.segment(r0, rows)).cast<float>();
      }
      if (t == 0) spent[cur] = stop.over_budget();
#pragma omp barrier
      // Only this round's sums are read here: y itself may already be
      // changing in another thread's next round.
      double total = 0.0, ynorm2 = 0.0, drift = 0.0;
      for (Index s = 0; s < nt; ++s) {
        total += change2[cur][s];
        ynorm2 += norm2[cur][s];
        drift += drift2[cur][s];
      }
      const double change = std::sqrt(total);
      at_reference = reference_stale(drift, ynorm2, change);
      if (t == 0) {
        summary.iterations = it + 1;
        summary.last_change = change;
      }
      // Every thread takes the same decision from the same sums.
      if (stop.converged(change, std::sqrt(ynorm2))) {
        if (t == 0) summary.stop = RoundStop::Tolerance;
        break;
      }
      if (spent[cur]) {
        if (t == 0) summary.stop = RoundStop::TimeBudget;
        break;
      }
    }
  }
  if (use_float) W.ref_valid = true;
  return summary;
}

AlternationResults run_serial(const FusedModel& M, FusedWorkspace& W, InputProjection<double>& projection,
                              const AlternationSettings& options, const detail::StopTest& stop,
                              Eigen::Ref<Vector<double>> y) {
  AlternationResults summary;
  for (int it = 0; it < options.iterations; ++it) {
    round_product(M, W, y.data(), options.float_products, it == 0 ? kNoChange : summary.last_change);
    summary.last_change = projection.project(W.g, y);
    summary.iterations = it + 1;
    if (stop.done(summary.last_change, [&] { return static_cast<double>(y.norm()); }, &summary)) break;
  }
  return summary;
}

}  // namespace qpreduce::detail
