// The rounds' product (round_product.h).
#include "round_product.h"

#include <algorithm>

namespace qpreduce::detail {

bool reference_stale(double drift2, double norm2, double change) {
  return !(drift2 <= kReferenceDrift * kReferenceDrift * norm2) ||
         !(drift2 <= kReferenceStep * kReferenceStep * change * change);
}

void double_product(const FusedModel& M, FusedWorkspace& W, const double* y, Index r0, Index r1, double* scratch) {
  W.g.segment(r0, r1 - r0) = W.gb.segment(r0, r1 - r0);
  M.rounds().add_rows(y, r0, r1, scratch, W.g.data());
}

void reference_product(const FusedModel& M, FusedWorkspace& W, const double* y, Index r0, Index r1, double* scratch) {
  const Index rows = r1 - r0;
  W.Fy_ref.segment(r0, rows).setZero();
  M.rounds().add_rows(y, r0, r1, scratch, W.Fy_ref.data());
  W.g.segment(r0, rows) = W.gb.segment(r0, rows) + W.Fy_ref.segment(r0, rows);
}

void difference_product(const FusedModel& M, FusedWorkspace& W, const float* yf, Index r0, Index r1, float* scratch_f) {
  const Index rows = r1 - r0;
  std::fill(W.gf.data() + r0, W.gf.data() + r1, 0.0f);
  M.rounds().add_rows(yf, r0, r1, scratch_f, W.gf.data());
  W.g.segment(r0, rows) = W.gb.segment(r0, rows) + W.Fy_ref.segment(r0, rows) + W.gf.segment(r0, rows).cast<double>();
}

bool near_reference(FusedWorkspace& W, const double* y, Index k, double change) {
  if (!W.ref_valid) return false;
  const Eigen::Map<const Vector<double>> yv(y, k);
  W.dy = yv - W.y_ref;  // vectorised passes: a scalar loop with two sums cost 5 % of a round at k = 243
  if (reference_stale(W.dy.squaredNorm(), yv.squaredNorm(), change)) return false;
  W.yf = W.dy.cast<float>();
  return true;
}

void round_product(const FusedModel& M, FusedWorkspace& W, const double* y, bool use_float, double change) {
  const Index q = M.q();
  if (!use_float) {
    double_product(M, W, y, 0, q, W.scratch.data());
  } else if (near_reference(W, y, M.k(), change)) {
    difference_product(M, W, W.yf.data(), 0, q, W.scratch_f.data());
  } else {
    W.y_ref = Eigen::Map<const Vector<double>>(y, M.k());
    reference_product(M, W, y, 0, q, W.scratch.data());
    W.ref_valid = true;
  }
}

}  // namespace qpreduce::detail
