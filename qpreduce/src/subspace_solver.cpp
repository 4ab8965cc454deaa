#include "qpreduce/subspace_solver.h"

#include "qpreduce/detail/timer.h"

#include <Eigen/Eigenvalues>
#include <Eigen/QR>
#include <fmt/format.h>

#include <cmath>

namespace qpreduce {

bool ConstraintOptions::is_valid(std::string* why) const {
  auto fail = [why](const char* msg) {
    if (why) *why = msg;
    return false;
  };
  if (soft && !(delta > 0.0 && std::isfinite(delta))) return fail("delta must be positive and finite");
  if (!(rank_tolerance > 0.0 && rank_tolerance < 1.0)) return fail("rank_tolerance must lie in (0, 1)");
  return true;
}

namespace {

using MatD = Matrix<double>;

// Inverse of a symmetric PSD matrix on its numerical range (pseudo-inverse),
// and whether it was singular.
MatD symmetric_pinv(const MatD& K, double tolerance, bool* singular, double* condition) {
  *singular = false;
  if (K.rows() == 0) {
    *condition = 1.0;
    return MatD(0, 0);
  }
  Eigen::SelfAdjointEigenSolver<MatD> es(0.5 * (K + K.transpose()));
  const Eigen::VectorXd& lambda = es.eigenvalues();
  const double top = lambda.cwiseAbs().maxCoeff();
  Eigen::VectorXd inv(lambda.size());
  for (Index i = 0; i < lambda.size(); ++i) {
    if (lambda(i) > tolerance * top && top > 0) {
      inv(i) = 1.0 / lambda(i);
    } else {
      inv(i) = 0.0;
      *singular = true;
    }
  }
  *condition = lambda.minCoeff() > 0 ? top / lambda.minCoeff() : INFINITY;
  return es.eigenvectors() * inv.asDiagonal() * es.eigenvectors().transpose();
}

}  // namespace

template <typename Scalar>
void SubspaceSolver<Scalar>::require_ready(const char* what) const {
  if (!ready_) {
    throw std::invalid_argument(std::string(what) + ": no subspace (precompute did not succeed)");
  }
}

template <typename Scalar>
void SubspaceSolver<Scalar>::require_constrained(const char* what) const {
  require_ready(what);
  if (!constrained_) throw std::invalid_argument(std::string(what) + ": call set_constraints first");
}

template <typename Scalar>
SubspaceSummary SubspaceSolver<Scalar>::precompute(const SparseMatrix<Scalar>& H, const SparseMatrix<Scalar>& C,
                                                   const SparseMatrix<Scalar>& D, const SubspaceOptions& options) {
  ready_ = constrained_ = false;
  SubspaceSummary summary = build_subspace(H, C, D, options, &subspace_);
  if (!summary.ok()) return summary;
  n_ = H.rows();
  const Index d = subspace_.N.cols(), k = subspace_.UD.cols();
  // H_r = BᵀHB with B = [N UD]; computed in double for symmetry and accuracy.
  MatD B(n_, d + k);
  B.leftCols(d) = subspace_.N.template cast<double>();
  B.rightCols(k) = subspace_.UD.template cast<double>();
  const SparseMatrix<double> Hd = H.template cast<double>();
  MatD HB = Hd * B;
  MatD Hr = B.transpose() * HB;
  Hr_ = (0.5 * (Hr + Hr.transpose())).template cast<Scalar>();
  BtD_ = MatD(D.template cast<double>().transpose() * B).transpose().template cast<Scalar>();
  ready_ = true;
  return summary;
}

template <typename Scalar>
ConstraintSummary SubspaceSolver<Scalar>::set_constraints(const SparseMatrix<Scalar>& A,
                                                          const ConstraintOptions& options) {
  std::string why;
  if (!options.is_valid(&why)) throw std::invalid_argument("ConstraintOptions: " + why);
  require_ready("SubspaceSolver::set_constraints");
  detail::check_size("SubspaceSolver::set_constraints: A rows", n_, A.rows());
  detail::check_finite("SubspaceSolver::set_constraints: A", A);
  const detail::Timer timer;
  constrained_ = false;
  ConstraintSummary summary;
  const Index d = this->d(), k = this->k(), p = d + k, m = A.cols();
  summary.m = m;

  // A_r = AᵀB: nnz(A)·p work for sparse A.
  MatD Ar(m, p);
  Ar.leftCols(d) = (A.transpose() * subspace_.N).template cast<double>();
  Ar.rightCols(k) = (A.transpose() * subspace_.UD).template cast<double>();
  const MatD Hr = Hr_.template cast<double>();
  MatD Mb, Mq;

  if (!options.soft) {
    // Rank-revealing QR of A_rᵀ (p×m): range(A_rᵀ) = row space, the rest of
    // Q spans ker(A_r).
    Eigen::ColPivHouseholderQR<MatD> qr(Ar.transpose());
    const double top = m > 0 ? qr.matrixQR().diagonal().cwiseAbs().maxCoeff() : 0.0;
    qr.setThreshold(options.rank_tolerance);
    const Index r = m > 0 && top > 0 ? qr.rank() : 0;
    summary.rank = r;
    const MatD Q = qr.householderQ();  // p×p
    const MatD Z = Q.rightCols(p - r);
    // Least-squares minimum-norm solution of A_r w = b: w0 = P·b.
    MatD P = MatD::Zero(p, m);
    if (r > 0) {
      Eigen::CompleteOrthogonalDecomposition<MatD> cod(Ar);
      cod.setThreshold(options.rank_tolerance);
      P = cod.pseudoInverse();
      const Eigen::JacobiSVD<MatD> svd(Ar);
      const auto& sv = svd.singularValues();
      summary.condition = sv(0) / sv(r - 1);
    }
    bool singular = false;
    double cond = 0;
    const MatD Kinv = symmetric_pinv(Z.transpose() * Hr * Z, options.rank_tolerance, &singular, &cond);
    Mq = Z * Kinv * Z.transpose();
    Mb = P - Mq * (Hr * P);
    if (singular) {
      summary.status = Status::Unbounded;
      summary.message = fmt::format(
          "the reduced energy is not strictly convex on the constraint set (ZᵀH_rZ is singular, condition {:.2e}): "
          "the minimiser is not unique or does not exist; the minimum-norm stationary point is returned",
          cond);
    } else if (r < m) {
      summary.status = Status::ConstraintsLeastSquares;
      summary.message = fmt::format(
          "{} hard constraints have rank {} in the subspace (over-determined or dependent): they hold in the "
          "least-squares sense",
          m, r);
    } else {
      summary.status = Status::Success;
      summary.message = fmt::format("{} hard constraints, rank {}", m, r);
    }
  } else {
    const double two_delta = 2.0 * options.delta;
    const MatD K = Hr + two_delta * (Ar.transpose() * Ar);
    bool singular = false;
    double cond = 0;
    Mq = symmetric_pinv(K, options.rank_tolerance, &singular, &cond);
    Mb = two_delta * (Mq * Ar.transpose());
    summary.rank = m > 0 ? Eigen::ColPivHouseholderQR<MatD>(Ar).rank() : 0;
    if (singular) {
      summary.status = Status::Unbounded;
      summary.message = fmt::format(
          "H_r + 2δA_rᵀA_r is singular (condition {:.2e}): the soft-constrained minimiser is not unique; the "
          "minimum-norm stationary point is returned",
          cond);
    } else {
      summary.status = Status::Success;
      summary.message = fmt::format("{} soft constraints, δ = {:.3g}", m, options.delta);
    }
  }

  Ar_ = Ar.template cast<Scalar>();
  Mb_ = Mb.template cast<Scalar>();
  Mq_ = Mq.template cast<Scalar>();
  MY_ = (Mq * BtD_.template cast<double>()).template cast<Scalar>();
  m_ = m;
  constrained_ = true;
  summary.seconds = timer.seconds();
  return summary;
}

template <typename Scalar>
void SubspaceSolver<Scalar>::reduce_linear_term(const ConstRef& q, Ref q_r) const {
  require_ready("SubspaceSolver::reduce_linear_term");
  detail::check_size("SubspaceSolver::reduce_linear_term: q size", n_, q.size());
  detail::check_size("SubspaceSolver::reduce_linear_term: q_r size", p(), q_r.size());
  q_r.head(d()).noalias() = subspace_.N.transpose() * q;
  q_r.tail(k()).noalias() = subspace_.UD.transpose() * q;
}

template <typename Scalar>
void SubspaceSolver<Scalar>::reduce_linear_term_in_D(const ConstRef& Y, Ref q_r) const {
  require_ready("SubspaceSolver::reduce_linear_term_in_D");
  detail::check_size("SubspaceSolver::reduce_linear_term_in_D: Y size", k(), Y.size());
  detail::check_size("SubspaceSolver::reduce_linear_term_in_D: q_r size", p(), q_r.size());
  q_r.noalias() = BtD_ * Y;
}

template <typename Scalar>
void SubspaceSolver<Scalar>::solve(const ConstRef& b, const ConstRef& q_r, Ref w) const {
  assert(constrained_ && b.size() == m_ && q_r.size() == p() && w.size() == p());
  w.noalias() = Mb_ * b;
  w.noalias() += Mq_ * q_r;
}

template <typename Scalar>
void SubspaceSolver<Scalar>::solve_in_D(const ConstRef& b, const ConstRef& Y, Ref w) const {
  assert(constrained_ && b.size() == m_ && Y.size() == k() && w.size() == p());
  w.noalias() = Mb_ * b;
  w.noalias() += MY_ * Y;
}

template <typename Scalar>
void SubspaceSolver<Scalar>::reconstruct(const ConstRef& w, Ref X) const {
  require_ready("SubspaceSolver::reconstruct");
  detail::check_size("SubspaceSolver::reconstruct: w size", p(), w.size());
  detail::check_size("SubspaceSolver::reconstruct: X size", n_, X.size());
  X.noalias() = subspace_.N * w.head(d());
  X.noalias() += subspace_.UD * w.tail(k());
}

template class SubspaceSolver<double>;
template class SubspaceSolver<float>;

}  // namespace qpreduce
