// The small dense equality-constrained QP shared by the reduced solvers:
//
//     min_w ½wᵀH w − gᵀw   s.t.  A w = c          (hard, Eq. 17 form)
//     min_w ½wᵀH w − gᵀw + δ‖A w − c‖²            (soft, Eq. 18 form)
//     H: p×p symmetric PSD, A: m×p
//
// has the solution w = M_c·c + M_g·g for every (c, g). This computes
// M_c (p×m) and M_g (p×p) once per constraint set. Hard constraints use the
// null-space method on a rank-revealing QR of Aᵀ; rank(A) < m gives the
// least-squares answer (Status::ConstraintsLeastSquares); a singular reduced
// Hessian gives the minimum-norm stationary point (Status::Unbounded).
#pragma once

#include "qpreduce/common.h"
#include "qpreduce/constraints.h"

namespace qpreduce::detail {

struct QpOperators {
  Matrix<double> Mc;  // p × m
  Matrix<double> Mg;  // p × p
};

QpOperators qp_operators(const Matrix<double>& H, const Matrix<double>& A, const ConstraintOptions& options,
                         ConstraintSummary* summary);

}  // namespace qpreduce::detail
