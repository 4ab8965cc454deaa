#include "qpreduce/full_solve.h"

#include "qpreduce/checks.h"
#include "qpreduce/util/timer.h"

namespace qpreduce {

template <typename Scalar>
FullSolveSummary solve_full(const SparseMatrix<Scalar>& H, const SparseMatrix<Scalar>& A,
                            const Vector<Scalar>& b, const Vector<Scalar>& q, Vector<Scalar>* X,
                            const SubspaceOptions& options) {
  if (X == nullptr) throw std::invalid_argument("solve_full: output pointer is null");
  check_size("solve_full: A rows", H.rows(), A.rows());
  check_size("solve_full: b size", A.cols(), b.size());
  check_size("solve_full: q size", H.rows(), q.size());
  check_finite("solve_full: b", b);
  check_finite("solve_full: q", q);
  const Timer timer;
  X->resize(0);
  const bool has_q = q.squaredNorm() > 0;
  SparseMatrix<Scalar> D(H.rows(), has_q ? 1 : 0);
  if (has_q) D = q.sparseView();
  SubspaceOptions opts = options;
  opts.check_dependent_cd = false;
  VariationalSubspace<Scalar> s;
  const SubspaceSummary sub = build_subspace(H, A, D, opts, &s);
  FullSolveSummary summary;
  summary.backend_used = sub.backend_used;
  summary.kkt_residual = sub.kkt_residual;
  summary.status = sub.status;
  if (!sub.ok()) {
    summary.message = "full-space solve (C = A, D = q): " + sub.message;
    summary.seconds = timer.seconds();
    return summary;
  }
  *X = s.N * b;
  if (has_q) *X += s.UD.col(0);
  summary.message = "solved";
  summary.seconds = timer.seconds();
  return summary;
}

template FullSolveSummary solve_full<double>(const SparseMatrix<double>&, const SparseMatrix<double>&,
                                             const Vector<double>&, const Vector<double>&, Vector<double>*,
                                             const SubspaceOptions&);
template FullSolveSummary solve_full<float>(const SparseMatrix<float>&, const SparseMatrix<float>&,
                                            const Vector<float>&, const Vector<float>&, Vector<float>*,
                                            const SubspaceOptions&);

void FullSolveSummary::add_details(Report* out) const {
  out->add("backend_used", backend_used)
      .add("kkt_residual", kkt_residual)
      .add("seconds", seconds);
}

}  // namespace qpreduce
