#include "qpreduce/factorization.h"

#include "blas.h"

#include <Eigen/OrderingMethods>
#include <Eigen/SparseCholesky>
#include <Eigen/SparseLU>

#include <cholmod.h>
#include <dlfcn.h>
#include <fmt/format.h>
#include <omp.h>

#include <algorithm>
#include <cassert>
#include <cmath>
#include <new>
#include <optional>
#include <stdexcept>

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

// The inertia test of an LDLᵀ factorization (which succeeds on indefinite
// matrices): an SPD matrix has only positive pivots, none within 1e3·ε of
// the largest. `pivot(j)` is D(j) for j < n; `who` names the backend in the
// message. Empty when the test holds, else why not.
template <typename Pivot>
std::string ldlt_inertia_failure(Index n, const Pivot& pivot, const char* who) {
  double scale = 0.0;
  Index negative = 0;
  for (Index j = 0; j < n; ++j) {
    scale = std::max(scale, std::abs(pivot(j)));
    if (!(pivot(j) >= 0.0)) ++negative;
  }
  if (negative > 0)
    return fmt::format("{}: matrix is not positive definite ({} negative pivots of {})", who, negative, n);
  Index tiny = 0;
  for (Index j = 0; j < n; ++j)
    if (std::abs(pivot(j)) <= 1e3 * Eigen::NumTraits<double>::epsilon() * scale) ++tiny;
  if (tiny > 0) return fmt::format("{}: matrix is numerically singular ({} pivots below 1e3·ε·max)", who, tiny);
  return {};
}

// Column blocks for a multi-right-hand-side solve: at most block_size wide,
// and (when threads > 1) a multiple of `threads` blocks of equal width so that
// no thread idles at the end.
struct ColumnBlocks {
  Index count = 0, width = 0;
};
ColumnBlocks column_blocks(Index cols, Index block_size, int threads) {
  ColumnBlocks b;
  if (cols <= 0) return b;
  block_size = std::max<Index>(1, block_size);
  b.count = (cols + block_size - 1) / block_size;
  if (threads > 1) b.count = ((b.count + threads - 1) / threads) * threads;
  b.count = std::min(b.count, cols);
  b.width = (cols + b.count - 1) / b.count;
  b.count = (cols + b.width - 1) / b.width;
  return b;
}

// CHOLMOD through the C API (not Eigen's wrapper), so that solves can run
// concurrently: each thread gets its own cholmod_common and workspace, and
// the factor is only read. Supernodal LLᵀ (Backend::Cholmod), or simplicial
// LDLᵀ (make_cholmod_simplicial_factorization), whose solves sweep the factor
// once for up to four right-hand sides together.
class CholmodFactorization final : public SparseFactorization {
 public:
  explicit CholmodFactorization(bool simplicial = false) {
    cholmod_start(&common_);
    common_.print = 0;  // failures are reported through info()/message()
    common_.error_handler = nullptr;
    common_.supernodal = simplicial ? CHOLMOD_SIMPLICIAL : CHOLMOD_SUPERNODAL;
    common_.final_ll = simplicial ? 0 : 1;  // LDLᵀ for the simplicial factor
    common_.final_asis = 1;                 // keep the factor as factored
    // Ordering: CHOLMOD's default (AMD, METIS only when AMD's fill is poor).
    // On the 500 × 500 grid METIS saves 17% of the factor (12.2M vs 14.8M
    // entries) but its analysis costs 2.3 s against AMD's 0.2 s, more than
    // the 300 solves gain (docs/performance.md).
  }
  ~CholmodFactorization() override {
    if (factor_) cholmod_free_factor(&factor_, &common_);
    cholmod_finish(&common_);
  }
  CholmodFactorization(const CholmodFactorization&) = delete;
  CholmodFactorization& operator=(const CholmodFactorization&) = delete;

  void setOrderingGroups(std::vector<Index> group) override { group_ = std::move(group); }

  void analyzePattern(const SparseMatrix<double>& A) override {
    if (factor_) cholmod_free_factor(&factor_, &common_);
    cholmod_sparse view = lower_view(A);
    if (!group_.empty()) {
      const std::vector<int> perm = grouped_ordering(A);
      if (perm.empty()) {
        set_info(Eigen::NumericalIssue,
                 fmt::format("CHOLMOD ordering of the grouped unknowns failed (status {})", common_.status));
        return;
      }
      // Only the given permutation (CHOLMOD still postorders it).
      const int nmethods = common_.nmethods, ordering = common_.method[0].ordering;
      common_.nmethods = 1;
      common_.method[0].ordering = CHOLMOD_GIVEN;
      factor_ = cholmod_analyze_p(&view, const_cast<int*>(perm.data()), nullptr, 0, &common_);
      common_.nmethods = nmethods;
      common_.method[0].ordering = ordering;
    } else {
      factor_ = cholmod_analyze(&view, &common_);
    }
    if (factor_ && common_.status >= CHOLMOD_OK) {
      set_info(Eigen::Success, "");
    } else {
      set_info(Eigen::NumericalIssue, fmt::format("CHOLMOD symbolic analysis failed (status {})", common_.status));
    }
  }
  void factorize(const SparseMatrix<double>& A) override {
    if (!factor_) {
      set_info(Eigen::InvalidInput, "CHOLMOD: factorize called before analyzePattern");
      return;
    }
    cholmod_sparse view = lower_view(A);
    cholmod_factorize(&view, factor_, &common_);
    const Index minor = static_cast<Index>(factor_->minor);
    if (common_.status == CHOLMOD_OK && minor >= A.rows()) {
      set_info(Eigen::Success, "");
      if (factor_->is_ll) {
        check_ll_pivots();
      } else {
        check_ldlt_pivots();
      }
    } else if (common_.status == CHOLMOD_NOT_POSDEF || minor < A.rows()) {
      set_info(Eigen::NumericalIssue,
               fmt::format("CHOLMOD: matrix is not positive definite (factorization stopped at column {} of {})",
                           minor, A.rows()));
    } else {
      set_info(Eigen::NumericalIssue, fmt::format("CHOLMOD: factorization failed (status {})", common_.status));
    }
  }
  Eigen::ComputationInfo info() const override { return info_; }
  const std::string& message() const override { return message_; }

  // With P·A·Pᵀ = L·Lᵀ (P = factor_->Perm), A⁻¹B = Pᵀ·L⁻ᵀ·L⁻¹·P·B. Each
  // column block is permuted, solved and permuted back in B's own storage
  // (cholmod_super_lsolve/ltsolve work in place), so a solve needs only an
  // n-vector and CHOLMOD's w × maxesize workspace per thread. cholmod_solve2
  // would hold two n × w copies per thread (Y = P·B and X), which at n ≈ 10⁵
  // and 300 columns was 200 MB on top of the factor and the solution.
  void solveInPlace(Matrix<double>& B, Index block_size) const override {
    assert(factor_ && info_ == Eigen::Success && B.rows() == static_cast<Index>(factor_->n));
    if (!factor_->is_super && !factor_->is_ll) {
      solve_simplicial(B, block_size);
      return;
    }
    if (!factor_->is_super || !factor_->is_ll) {
      throw std::logic_error("CHOLMOD: the factor is not a supernodal LLᵀ (the in-place solve needs one)");
    }
    const Index n = B.rows();
    int threads = omp_in_parallel() ? 1 : omp_get_max_threads();
    const ColumnBlocks blocks = column_blocks(B.cols(), block_size, threads);
    threads = static_cast<int>(std::min<Index>(threads, blocks.count));
    if (blocks.count == 0) return;
    // One BLAS thread per concurrent solve; a single solve keeps the BLAS's own threads.
    std::optional<detail::ScopedBlasThreads> blas;
    if (threads > 1) blas.emplace(1);
    const int* perm = static_cast<const int*>(factor_->Perm);
    int failed = 0;  // 1: no workspace, 2: CHOLMOD refused the solve
#pragma omp parallel num_threads(threads) reduction(max : failed)
    {
      cholmod_common c;
      cholmod_start(&c);
      c.print = 0;
      c.error_handler = nullptr;
      const size_t esize = std::max<size_t>(factor_->maxesize, 1);
      cholmod_dense* E = cholmod_allocate_dense(esize, static_cast<size_t>(blocks.width), esize, CHOLMOD_REAL, &c);
      Eigen::VectorXd scratch(n);
#pragma omp for schedule(dynamic, 1)
      for (Index b = 0; b < blocks.count; ++b) {
        const Index j = b * blocks.width, w = std::min(blocks.width, B.cols() - j);
        if (E == nullptr) {
          failed = 1;
          continue;
        }
        for (Index col = j; col < j + w; ++col) {  // B(:, col) ← P·B(:, col)
          double* x = B.col(col).data();
          scratch = B.col(col);
          for (Index k = 0; k < n; ++k) x[k] = scratch[perm[k]];
        }
        cholmod_dense X = dense_view(B, j, w);
        if (!cholmod_super_lsolve(factor_, &X, E, &c) || !cholmod_super_ltsolve(factor_, &X, E, &c)) {
          failed = std::max(failed, 2);
          continue;
        }
        for (Index col = j; col < j + w; ++col) {  // B(:, col) ← Pᵀ·B(:, col)
          double* x = B.col(col).data();
          scratch = B.col(col);
          for (Index k = 0; k < n; ++k) x[perm[k]] = scratch[k];
        }
      }
      cholmod_free_dense(&E, &c);
      cholmod_finish(&c);
    }
    if (failed == 1) throw std::bad_alloc();
    if (failed == 2) throw std::runtime_error("CHOLMOD: the supernodal solve failed (problem too large for the BLAS)");
  }
  Backend backend() const override { return Backend::Cholmod; }
  Index factorNonZeros() const override {
    if (!factor_) return 0;
    return static_cast<Index>(factor_->is_super ? factor_->xsize : factor_->nzmax);
  }

 private:
  // A cholmod_dense view (no copy) of B's columns j … j + w − 1.
  static cholmod_dense dense_view(Matrix<double>& B, Index j, Index w) {
    cholmod_dense v{};
    v.nrow = static_cast<size_t>(B.rows());
    v.ncol = static_cast<size_t>(w);
    v.d = static_cast<size_t>(B.outerStride());
    v.nzmax = v.d * v.ncol;
    v.x = B.col(j).data();
    v.xtype = CHOLMOD_REAL;
    v.dtype = CHOLMOD_DOUBLE;
    return v;
  }
  // An LLᵀ stops at a pivot ≤ 0, but a singular positive semidefinite matrix
  // can end with a pivot of round-off size on either side of 0 (which side
  // depends on the BLAS kernels' rounding): the same relative test as the
  // LDLᵀ's, on d_j = L_jj² (cholmod_rcond is min d_j / max d_j).
  void check_ll_pivots() {
    if (factor_->n == 0) return;
    const double rcond = cholmod_rcond(factor_, &common_);
    if (!(rcond > 1e3 * Eigen::NumTraits<double>::epsilon())) {
      set_info(Eigen::NumericalIssue,
               fmt::format("CHOLMOD LLᵀ: matrix is numerically singular (pivot ratio {:.2e}, below 1e3·ε)", rcond));
    }
  }
  // A simplicial LDLᵀ succeeds on indefinite matrices: the inertia of D
  // (the first entry of each column of the factor) says whether A was
  // positive definite.
  void check_ldlt_pivots() {
    const auto* p = static_cast<const int*>(factor_->p);
    const auto* x = static_cast<const double*>(factor_->x);
    std::string why = ldlt_inertia_failure(
        static_cast<Index>(factor_->n), [&](Index j) { return x[p[j]]; }, "CHOLMOD LDLᵀ");
    if (!why.empty()) set_info(Eigen::NumericalIssue, std::move(why));
  }
  // The simplicial factor's solve: cholmod_solve2 per column block, with
  // each thread's own workspace (X, Y, E), copied back into B.
  void solve_simplicial(Matrix<double>& B, Index block_size) const {
    const Index n = B.rows();
    int threads = omp_in_parallel() ? 1 : omp_get_max_threads();
    const ColumnBlocks blocks = column_blocks(B.cols(), block_size, threads);
    threads = static_cast<int>(std::min<Index>(threads, blocks.count));
    if (blocks.count == 0) return;
    int failed = 0;  // 1: CHOLMOD refused the solve
#pragma omp parallel num_threads(threads) reduction(max : failed)
    {
      cholmod_common c;
      cholmod_start(&c);
      c.print = 0;
      c.error_handler = nullptr;
      cholmod_dense *X = nullptr, *Y = nullptr, *E = nullptr;
#pragma omp for schedule(dynamic, 1)
      for (Index b = 0; b < blocks.count; ++b) {
        const Index j = b * blocks.width, w = std::min(blocks.width, B.cols() - j);
        cholmod_dense Bv = dense_view(B, j, w);
        if (!cholmod_solve2(CHOLMOD_A, factor_, &Bv, nullptr, &X, nullptr, &Y, &E, &c)) {
          failed = 1;
          continue;
        }
        B.middleCols(j, w) = Eigen::Map<const Matrix<double>, 0, Eigen::OuterStride<>>(
            static_cast<const double*>(X->x), n, w, Eigen::OuterStride<>(static_cast<Index>(X->d)));
      }
      cholmod_free_dense(&X, &c);
      cholmod_free_dense(&Y, &c);
      cholmod_free_dense(&E, &c);
      cholmod_finish(&c);
    }
    if (failed == 1) throw std::runtime_error("CHOLMOD: the simplicial solve failed (out of memory?)");
  }
  // A cholmod_sparse view (no copy) of the lower triangle (stype = −1) of a
  // compressed, sorted n × n matrix given by its column pointers and row
  // indices; values x, or a pattern when x is null.
  static cholmod_sparse lower_view(Index n, const int* p, const int* i, const double* x) {
    cholmod_sparse v{};
    v.nrow = v.ncol = static_cast<size_t>(n);
    v.nzmax = static_cast<size_t>(p[n]);
    v.p = const_cast<int*>(p);
    v.i = const_cast<int*>(i);
    v.x = const_cast<double*>(x);
    v.stype = -1;
    v.itype = CHOLMOD_INT;
    v.xtype = x ? CHOLMOD_REAL : CHOLMOD_PATTERN;
    v.dtype = CHOLMOD_DOUBLE;
    v.sorted = 1;
    v.packed = 1;
    return v;
  }
  static cholmod_sparse lower_view(const SparseMatrix<double>& A) {
    if (!A.isCompressed()) throw std::invalid_argument("CHOLMOD backend: matrix must be compressed");
    return lower_view(A.rows(), A.outerIndexPtr(), A.innerIndexPtr(), A.valuePtr());
  }
  void set_info(Eigen::ComputationInfo info, std::string message) {
    info_ = info;
    message_ = std::move(message);
  }

  // The quotient graph of A's pattern under group_ (g × g, both triangles),
  // ordered by AMD and by METIS (CHOLMOD keeps the better by its flop
  // count), expanded to the unknowns: each group's members in a row, in
  // index order. Empty on failure.
  std::vector<int> grouped_ordering(const SparseMatrix<double>& A) {
    const Index n = A.rows();
    if (static_cast<Index>(group_.size()) != n) {
      throw std::invalid_argument(fmt::format("CHOLMOD ordering groups: {} entries for {} unknowns", group_.size(), n));
    }
    Index g = 0;
    for (Index x : group_) {
      if (x < 0) throw std::invalid_argument(fmt::format("CHOLMOD ordering groups: negative group {}", x));
      g = std::max(g, x + 1);
    }
    // Members of each group (CSR).
    std::vector<int> start(static_cast<size_t>(g) + 1, 0), member(static_cast<size_t>(n));
    for (Index i = 0; i < n; ++i) ++start[static_cast<size_t>(group_[i]) + 1];
    for (Index q = 0; q < g; ++q) start[q + 1] += start[q];
    {
      std::vector<int> next(start.begin(), start.end() - 1);
      for (Index i = 0; i < n; ++i) member[next[group_[i]]++] = static_cast<int>(i);
    }
    // Quotient pattern, column by column with a marker (A is symmetric, so
    // the columns of a group's members give its neighbours).
    std::vector<int> qp(static_cast<size_t>(g) + 1, 0), qi, mark(static_cast<size_t>(g), -1);
    for (Index q = 0; q < g; ++q) {
      for (int t = start[q]; t < start[q + 1]; ++t)
        for (SparseMatrix<double>::InnerIterator it(A, member[t]); it; ++it) {
          const int r = static_cast<int>(group_[it.row()]);
          if (mark[r] != q) {
            mark[r] = static_cast<int>(q);
            qi.push_back(r);
          }
        }
      std::sort(qi.begin() + qp[q], qi.end());
      qp[q + 1] = static_cast<int>(qi.size());
    }
    cholmod_sparse quotient = lower_view(g, qp.data(), qi.data(), nullptr);
    // Both AMD and METIS: CHOLMOD's default rule (METIS only when AMD's fill
    // is poor) would judge the quotient graph's own fill, which understates
    // the unknowns' (on the Bumpy Plane the default rule's choice gave 50.7M
    // factor entries, trying both 45.7M).
    const int nmethods = common_.nmethods, first = common_.method[0].ordering, second = common_.method[1].ordering;
    common_.nmethods = 2;
    common_.method[0].ordering = CHOLMOD_AMD;
    common_.method[1].ordering = CHOLMOD_METIS;
    cholmod_factor* symbolic = cholmod_analyze(&quotient, &common_);
    common_.nmethods = nmethods;
    common_.method[0].ordering = first;
    common_.method[1].ordering = second;
    if (symbolic == nullptr || common_.status < CHOLMOD_OK) {
      if (symbolic) cholmod_free_factor(&symbolic, &common_);
      return {};
    }
    const int* qperm = static_cast<const int*>(symbolic->Perm);
    std::vector<int> perm;
    perm.reserve(static_cast<size_t>(n));
    for (Index k = 0; k < g; ++k)
      for (int t = start[qperm[k]]; t < start[qperm[k] + 1]; ++t) perm.push_back(member[t]);
    cholmod_free_factor(&symbolic, &common_);
    return perm;
  }

  std::vector<Index> group_;
  mutable cholmod_common common_;
  cholmod_factor* factor_ = nullptr;
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
    const Eigen::VectorXd d = ldlt_.vectorD();
    message_ = ldlt_inertia_failure(
        d.size(), [&](Index j) { return d(j); }, "SimplicialLDLT");
    info_ = message_.empty() ? Eigen::Success : Eigen::NumericalIssue;
  }
  Eigen::ComputationInfo info() const override { return info_; }
  const std::string& message() const override { return message_; }
  void solveInPlace(Matrix<double>& B, Index block_size) const override {
    const int threads = omp_in_parallel() ? 1 : omp_get_max_threads();
    const ColumnBlocks blocks = column_blocks(B.cols(), block_size, threads);
    // SimplicialLDLT::solve is const and keeps no shared scratch state, so
    // column blocks are independent.
#pragma omp parallel for schedule(dynamic, 1) num_threads(threads)
    for (Index b = 0; b < blocks.count; ++b) {
      const Index j = b * blocks.width;
      const Index w = std::min(blocks.width, B.cols() - j);
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

namespace detail {

ScopedBlasThreads::ScopedBlasThreads(int threads) {
  using Get = int (*)();
  using Set = void (*)(int);
  static const auto get = reinterpret_cast<Get>(dlsym(RTLD_DEFAULT, "openblas_get_num_threads"));
  static const auto set = reinterpret_cast<Set>(dlsym(RTLD_DEFAULT, "openblas_set_num_threads"));
  if (get && set) {
    previous_ = get();
    if (previous_ != threads) {
      set_ = set;
      set_(threads);
    }
  }
}

ScopedBlasThreads::~ScopedBlasThreads() {
  if (set_) set_(previous_);
}

}  // namespace detail

std::unique_ptr<SparseFactorization> make_factorization(Backend backend) {
  switch (backend) {
    case Backend::Auto:
    case Backend::Cholmod: return std::make_unique<CholmodFactorization>();
    case Backend::SimplicialLDLT: return std::make_unique<SimplicialFactorization>();
    case Backend::SparseLU: return std::make_unique<LUFactorization>();
  }
  throw std::invalid_argument("make_factorization: unknown backend");
}

std::unique_ptr<SparseFactorization> make_cholmod_simplicial_factorization() {
  return std::make_unique<CholmodFactorization>(true);
}

}  // namespace qpreduce
