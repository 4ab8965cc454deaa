#include "qpreduce/factorization.h"

#include <Eigen/CholmodSupport>
#include <Eigen/OrderingMethods>
#include <Eigen/SparseCholesky>
#include <Eigen/SparseLU>

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

namespace qpreduce {

const char* to_string(Backend backend) {
  switch (backend) {
    case Backend::Auto: return "auto";
    case Backend::Cholmod: return "cholmod-supernodal";
    case Backend::SimplicialLDLT: return "eigen-simplicial-ldlt";
    case Backend::SparseLU: return "eigen-sparse-lu";
  }
  return "unknown";
}

namespace {

// CholmodSupernodalLLT with access to the column where a failed factorization
// stopped and to the factor size.
class CholmodLLT : public Eigen::CholmodSupernodalLLT<SparseMatrix<double>, Eigen::Lower> {
 public:
  Index minor() const { return m_cholmodFactor ? static_cast<Index>(m_cholmodFactor->minor) : -1; }
  Index factor_size() const {
    if (!m_cholmodFactor) return 0;
    return static_cast<Index>(m_cholmodFactor->is_super ? m_cholmodFactor->xsize
                                                         : m_cholmodFactor->nzmax);
  }
};

class CholmodFactorization final : public SparseFactorization {
 public:
  CholmodFactorization() { llt_.cholmod().print = 0; }  // failures are reported through info()/message()
  void analyzePattern(const SparseMatrix<double>& A) override {
    llt_.analyzePattern(A);
    set_info(llt_.info(), "CHOLMOD symbolic analysis failed");
  }
  void factorize(const SparseMatrix<double>& A) override {
    llt_.factorize(A);
    if (llt_.info() == Eigen::Success) {
      info_ = Eigen::Success;
      message_.clear();
    } else {
      info_ = Eigen::NumericalIssue;
      message_ = fmt::format(
          "CHOLMOD: matrix is not positive definite (factorization stopped at column {} of {})",
          llt_.minor(), A.rows());
    }
  }
  Eigen::ComputationInfo info() const override { return info_; }
  const std::string& message() const override { return message_; }
  void solveInPlace(Matrix<double>& B, Index block_size) const override {
    // CHOLMOD's supernodal solve is BLAS-3 over the whole block; blocks bound
    // the temporary CHOLMOD allocates for its result.
    block_size = std::max<Index>(1, block_size);
    for (Index j = 0; j < B.cols(); j += block_size) {
      const Index w = std::min(block_size, B.cols() - j);
      Matrix<double> x = llt_.solve(B.middleCols(j, w));
      B.middleCols(j, w) = x;
    }
  }
  Backend backend() const override { return Backend::Cholmod; }
  Index factorNonZeros() const override { return llt_.factor_size(); }

 private:
  void set_info(Eigen::ComputationInfo info, const char* what) {
    info_ = info;
    message_ = info == Eigen::Success ? std::string() : std::string(what);
  }
  CholmodLLT llt_;
  Eigen::ComputationInfo info_ = Eigen::InvalidInput;
  std::string message_ = "not factorized";
};

class SimplicialFactorization final : public SparseFactorization {
 public:
  void analyzePattern(const SparseMatrix<double>& A) override {
    ldlt_.analyzePattern(A);
    info_ = ldlt_.info();
    message_ = info_ == Eigen::Success ? "" : "SimplicialLDLT symbolic analysis failed";
  }
  void factorize(const SparseMatrix<double>& A) override {
    ldlt_.factorize(A);
    if (ldlt_.info() != Eigen::Success) {
      info_ = Eigen::NumericalIssue;
      message_ = "SimplicialLDLT: zero pivot (matrix is singular)";
      return;
    }
    // Inertia from the pivots: an SPD matrix has only positive ones.
    const Eigen::VectorXd d = ldlt_.vectorD();
    const double scale = d.cwiseAbs().maxCoeff();
    const Index negative = (d.array() < 0.0).count();
    const Index tiny = (d.array().abs() <= 1e3 * Eigen::NumTraits<double>::epsilon() * scale).count();
    if (negative > 0) {
      info_ = Eigen::NumericalIssue;
      message_ = fmt::format("SimplicialLDLT: matrix is not positive definite ({} negative pivots of {})",
                             negative, d.size());
    } else if (tiny > 0) {
      info_ = Eigen::NumericalIssue;
      message_ = fmt::format("SimplicialLDLT: matrix is numerically singular ({} pivots below 1e3·ε·max)", tiny);
    } else {
      info_ = Eigen::Success;
      message_.clear();
    }
  }
  Eigen::ComputationInfo info() const override { return info_; }
  const std::string& message() const override { return message_; }
  void solveInPlace(Matrix<double>& B, Index block_size) const override {
    block_size = std::max<Index>(1, block_size);
    const Index blocks = (B.cols() + block_size - 1) / block_size;
    // SimplicialLDLT::solve is const and keeps no shared scratch state, so
    // column blocks are independent.
#pragma omp parallel for schedule(dynamic)
    for (Index b = 0; b < blocks; ++b) {
      const Index j = b * block_size;
      const Index w = std::min(block_size, B.cols() - j);
      Matrix<double> x = ldlt_.solve(B.middleCols(j, w));
      B.middleCols(j, w) = x;
    }
  }
  Backend backend() const override { return Backend::SimplicialLDLT; }
  Index factorNonZeros() const override { return ldlt_.matrixL().nestedExpression().nonZeros() + ldlt_.rows(); }

 private:
  Eigen::SimplicialLDLT<SparseMatrix<double>, Eigen::Lower, Eigen::AMDOrdering<int>> ldlt_;
  Eigen::ComputationInfo info_ = Eigen::InvalidInput;
  std::string message_ = "not factorized";
};

class LUFactorization final : public SparseFactorization {
 public:
  void analyzePattern(const SparseMatrix<double>& A) override {
    lu_.analyzePattern(A);
    info_ = Eigen::Success;
    message_.clear();
  }
  void factorize(const SparseMatrix<double>& A) override {
    lu_.factorize(A);
    info_ = lu_.info();
    // SparseLU may succeed on a numerically singular matrix; callers check
    // residuals and the rank of what they build from the solves.
    message_ = info_ == Eigen::Success ? "" : "SparseLU: matrix is singular (" + lu_.lastErrorMessage() + ")";
  }
  Eigen::ComputationInfo info() const override { return info_; }
  const std::string& message() const override { return message_; }
  void solveInPlace(Matrix<double>& B, Index block_size) const override {
    block_size = std::max<Index>(1, block_size);
    // SparseLU::solve is not const-safe across threads (it uses member
    // scratch in some Eigen versions), so blocks run in sequence.
    for (Index j = 0; j < B.cols(); j += block_size) {
      const Index w = std::min(block_size, B.cols() - j);
      Matrix<double> x = const_cast<Eigen::SparseLU<SparseMatrix<double>>&>(lu_).solve(B.middleCols(j, w));
      B.middleCols(j, w) = x;
    }
  }
  Backend backend() const override { return Backend::SparseLU; }
  Index factorNonZeros() const override { return lu_.nnzL() + lu_.nnzU(); }

 private:
  Eigen::SparseLU<SparseMatrix<double>, Eigen::COLAMDOrdering<int>> lu_;
  Eigen::ComputationInfo info_ = Eigen::InvalidInput;
  std::string message_ = "not factorized";
};

}  // namespace

std::unique_ptr<SparseFactorization> make_factorization(Backend backend) {
  switch (backend) {
    case Backend::Auto:
    case Backend::Cholmod: return std::make_unique<CholmodFactorization>();
    case Backend::SimplicialLDLT: return std::make_unique<SimplicialFactorization>();
    case Backend::SparseLU: return std::make_unique<LUFactorization>();
  }
  throw std::invalid_argument("make_factorization: unknown backend");
}

}  // namespace qpreduce
