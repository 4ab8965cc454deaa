#include "qpreduce/alternating.h"

#include "blas.h"
#include "range_space.h"
#include "simd_kernels.h"

#include "qp_operators.h"
#include "qpreduce/support.h"

#include <fmt/format.h>

#include <omp.h>

#include <cstring>
#include <memory>
#include <optional>
#include <type_traits>

namespace qpreduce {

bool AlternatingOptions::is_valid(std::string* why) const {
  if (iterations < 1) {
    if (why) *why = fmt::format("iterations must be at least 1, got {}", iterations);
    return false;
  }
  if (!(tolerance >= 0.0)) {
    if (why) *why = "tolerance must be non-negative";
    return false;
  }
  if (threads < 0) {
    if (why) *why = fmt::format("threads must be ≥ 0 (0: all), got {}", threads);
    return false;
  }
  if (parallel_min_entries < 0) {
    if (why) *why = fmt::format("parallel_min_entries must be ≥ 0, got {}", parallel_min_entries);
    return false;
  }
  return true;
}

namespace detail {

// The fast path's per-solver part (alternating.h), in double.
struct FixedCoordinatePrep {
  std::uint64_t generation = 0;  // SubspaceSolver::generation_ it was made from
  RangeSpace range;              // of H_zz (d × d)
  Matrix<double> G;              // NᵀD − H_zy (d × k)
  Matrix<double> P0;             // M0·G (d × k): the unconstrained z-response to Y
  Matrix<double> LtG;            // LᵀG (ν × k), L = D_sV_L/σ the lifted directions
};

}  // namespace detail

template <typename Scalar>
ConstraintSummary FixedCoordinateSolver<Scalar>::set_constraints(const SubspaceSolver<Scalar>& solver,
                                                                 const SparseMatrix<Scalar>& A,
                                                                 const ConstraintOptions& options) {
  using MatD = Matrix<double>;
  // (set_reduced_constraints checks the options and the rest.)
  if (!solver.ready()) {
    throw std::invalid_argument("FixedCoordinateSolver::set_constraints: the subspace solver is not ready");
  }
  check_size("FixedCoordinateSolver::set_constraints: A rows", solver.n(), A.rows());
  check_finite("FixedCoordinateSolver::set_constraints: A", A);
  const Timer timer;
  const MatD Az = (A.transpose() * solver.subspace().N).template cast<double>();
  const MatD Ay = (A.transpose() * solver.subspace().UD).template cast<double>();
  ConstraintSummary summary = set_reduced_constraints(solver, Az, Ay, options);
  summary.seconds = timer.seconds();
  return summary;
}

template <typename Scalar>
ConstraintSummary FixedCoordinateSolver<Scalar>::set_reduced_constraints(const SubspaceSolver<Scalar>& solver,
                                                                         const Matrix<double>& Az,
                                                                         const Matrix<double>& Ay,
                                                                         const ConstraintOptions& options) {
  using MatD = Matrix<double>;
  std::string why;
  if (!options.is_valid(&why)) throw std::invalid_argument("ConstraintOptions: " + why);
  if (!solver.ready()) {
    throw std::invalid_argument("FixedCoordinateSolver::set_reduced_constraints: the subspace solver is not ready");
  }
  check_size("FixedCoordinateSolver::set_reduced_constraints: A_z columns (d)", solver.d(), Az.cols());
  check_size("FixedCoordinateSolver::set_reduced_constraints: A_y columns (k)", solver.k(), Ay.cols());
  check_size("FixedCoordinateSolver::set_reduced_constraints: A_y rows (as A_z)", Az.rows(), Ay.rows());
  check_finite("FixedCoordinateSolver::set_reduced_constraints: A_z", Az);
  check_finite("FixedCoordinateSolver::set_reduced_constraints: A_y", Ay);
  const Timer timer;
  ready_ = false;
  fast_ = false;
  const Index d = solver.d(), k = solver.k(), m = Az.rows();

  std::optional<detail::ScopedBlasThreads> blas;  // single-threaded BLAS unless asked (see ConstraintOptions)
  if (options.threads > 0) blas.emplace(options.threads);
  ConstraintSummary summary;
  summary.m = m;
  if (options.fast_path) {
    prepare_impl(solver);
    detail::RangeSpaceOperators rso;
    if (detail::range_space_operators(prep_->range, Az, options, &summary, &rso)) {
      // M_b = T's first m columns, M_Y = P0 − T·R with
      // R = Y'ᵀG + [A_y; 0] = [A_z·P0 + A_y; LᵀG] (M0 symmetric).
      // In double M_Y stays factored (solve applies P0 − T·R): forming it is
      // d·μ·k multiply-adds and two passes over d × k per constraint set.
      const Index mu = rso.T.cols();
      R_.resize(mu, k);
      R_.topRows(m) = Ay;
      detail::blas_gemm(false, false, 1.0, Az, prep_->P0, 1.0, R_.topRows(m));
      R_.bottomRows(mu - m) = prep_->LtG;
      if (R_.allFinite() && rso.T.allFinite()) {
        fast_ = true;
        Mb_ = rso.T.leftCols(m);
        T_ = std::move(rso.T);
        MY_.resize(0, 0);  // kept factored
        ry_.resize(mu);
      }
    }
  }
  if (!fast_) {
    // The null-space method on H_zz (detail/qp_operators.h).
    summary = ConstraintSummary{};
    const MatD Hr = solver.reduced_hessian().template cast<double>();
    const MatD G = solver.reduced_linear_map().topRows(d).template cast<double>() - Hr.topRightCorner(d, k);
    const detail::QpOperators ops = detail::qp_operators(Hr.topLeftCorner(d, d), Az, options, &summary);
    Mb_ = ops.Mc;
    MatD MY(d, k);  // M_g·G − M_c·A_y, through the BLAS (blas.h)
    detail::blas_gemm(false, false, 1.0, ops.Mg, G, 0.0, MY);
    detail::blas_gemm(false, false, -1.0, ops.Mc, Ay, 1.0, MY);
    MY_ = std::move(MY);
  }
  k_ = k;
  summary.fast_path = fast_;
  ready_ = true;
  summary.seconds = timer.seconds();
  return summary;
}

template <typename Scalar>
void FixedCoordinateSolver<Scalar>::prepare(const SubspaceSolver<Scalar>& solver) {
  if (!solver.ready()) throw std::invalid_argument("FixedCoordinateSolver::prepare: the subspace solver is not ready");
  const detail::ScopedBlasThreads blas(1);  // single-threaded BLAS, as set_constraints by default
  prepare_impl(solver);
}

template <typename Scalar>
void FixedCoordinateSolver<Scalar>::prepare_impl(const SubspaceSolver<Scalar>& solver) {
  if (prep_ && prep_->generation == solver.generation_) return;
  const Index d = solver.d(), k = solver.k();
  auto prep = std::make_shared<detail::FixedCoordinatePrep>();
  prep->generation = solver.generation_;
  prep->range = detail::prepare_range_space(solver.Hr_d_.topLeftCorner(d, d), solver.lift_tolerance_);
  prep->G = solver.BtD_d_.topRows(d) - solver.Hr_d_.topRightCorner(d, k);
  prep->P0.resize(d, k);
  detail::blas_gemm(false, false, 1.0, prep->range.Minv0, prep->G, 0.0, prep->P0);
  prep->LtG.resize(prep->range.lift_cols.cols(), k);
  detail::blas_gemm(true, false, 1.0, prep->range.lift_cols, prep->G, 0.0, prep->LtG);
  prep_ = std::move(prep);
}

template <typename Scalar>
Matrix<Scalar> FixedCoordinateSolver<Scalar>::MY() const {
  if (!fast_) return MY_;
  Matrix<double> MY = prep_->P0;
  detail::blas_gemm(false, false, -1.0, T_, R_, 1.0, MY);
  return MY;
}

template <typename Scalar>
void FixedCoordinateSolver<Scalar>::solve(const ConstRef& b, const ConstRef& Y, Ref z) const {
  assert(ready_ && b.size() == m() && Y.size() == k() && z.size() == d());
  detail::gemv(Mb_, b.data(), z.data(), false);
  if (fast_) {
    // z += P0·Y − T·(R·Y); ry_ is μ scratch.
    detail::gemv(prep_->P0, Y.data(), z.data(), true);
    detail::gemv(R_, Y.data(), ry_.data(), false);
    ry_ = -ry_;
    detail::gemv(T_, ry_.data(), z.data(), true);
    return;
  }
  detail::gemv(MY_, Y.data(), z.data(), true);
}

namespace {

// Columns per block when the fast path forms F_y and its float copy: a
// q × 32 double block stays in L2 until it is copied (q = 9d ≤ 1000 →
// ≤ 256 KiB).
constexpr Index kColumnBlock = 32;

// Same shape and the same bits.
template <typename T>
bool same_matrix(const Matrix<T>& a, const Matrix<T>& b) {
  return a.rows() == b.rows() && a.cols() == b.cols() &&
         (a.size() == 0 || std::memcmp(a.data(), b.data(), sizeof(T) * static_cast<size_t>(a.size())) == 0);
}

}  // namespace

template <typename Scalar>
void FusedAlternation<Scalar>::set(const FixedCoordinateSolver<Scalar>& phase1, const Matrix<Scalar>& Gz,
                                   const Matrix<Scalar>& Gy, int threads, FusedForm form, FusedPrecision precision) {
  set_impl(phase1, Gz, Gy, threads, form, precision, false);
}

template <typename Scalar>
void FusedAlternation<Scalar>::set(const FixedCoordinateSolver<Scalar>& phase1, int threads, FusedForm form,
                                   FusedPrecision precision) {
  if (!inputs_ready_) throw std::invalid_argument("FusedAlternation::set: no G_z, G_y given yet");
  set_impl(phase1, Gz_, Gy_, threads, form, precision, true);
}

template <typename Scalar>
void FusedAlternation<Scalar>::set_impl(const FixedCoordinateSolver<Scalar>& phase1, const Matrix<Scalar>& Gz,
                                        const Matrix<Scalar>& Gy, int threads, FusedForm form,
                                        FusedPrecision precision, bool same_inputs) {
  (void)precision;  // (double only)
  std::optional<detail::ScopedBlasThreads> blas;  // single-threaded BLAS unless asked (see ConstraintOptions)
  if (threads > 0) blas.emplace(threads);
  if (!phase1.ready()) throw std::invalid_argument("FusedAlternation::set: Phase 1 has no constraints yet");
  check_size("FusedAlternation::set: G_z columns (d)", phase1.d(), Gz.cols());
  check_size("FusedAlternation::set: G_y columns (k)", phase1.k(), Gy.cols());
  check_size("FusedAlternation::set: G_y rows (as G_z)", Gz.rows(), Gy.rows());
  ready_ = false;
  factored_ = false;
  float_set_ = false;
  if (!same_inputs) keep_inputs(Gz, Gy);
  const Index q = Gz.rows(), k = Gy.cols();
  bool fast = false;
  if constexpr (std::is_same_v<Scalar, double>) {
    if (phase1.fast_) {
      form_c0(phase1, Gz);
      const bool factored =
          form == FusedForm::Factored || (form == FusedForm::Automatic && q * k > kExplicitMaxEntries);
      // G_z·T (q × μ) and F_b = G_z·M_b, its first m columns.
      const Index m = phase1.m(), mu = phase1.T_.cols();
      Matrix<double> GzT;
      if (factored && precision == FusedPrecision::Float) {
        form_gz_float(Gz);
        const Matrix<float> Tf = phase1.T_.template cast<float>();
        GzT_f_.resize(q, mu);
        detail::blas_gemm(false, false, 1.0, Gz_f_, Tf, 0.0, GzT_f_);
        Fb_ = GzT_f_.leftCols(m).template cast<double>();
      } else {
        GzT.resize(q, mu);
        detail::blas_gemm(false, false, 1.0, Gz, phase1.T_, 0.0, GzT);
        Fb_ = GzT.leftCols(m);
      }
      if (factored) {
        // F₀ = C0 + G_y, once per (C0, G_y); the rank-μ part stays factored.
        if (!base_ready_) {
          check_finite("FusedAlternation::set: G_y", Gy);
          Fy_ = C0_ + Gy;
          Fy_f_ = Fy_.template cast<float>();
          base_ready_ = true;
        }
        GzT_ = std::move(GzT);  // empty after a Float set
        if (precision == FusedPrecision::Double) GzT_f_ = GzT_.cast<float>();
        float_set_ = precision == FusedPrecision::Float;
        R_ = phase1.R_;
        R_f_ = R_.cast<float>();
        ry_.resize(R_.rows());
        ryf_.resize(R_.rows());
        factored_ = true;
      } else {
        // F_y = C0 + G_y − (G_z·T)·R, in column blocks that are still in
        // cache for the float copy.
        base_ready_ = false;  // Fy_ holds this constraint set's F_y
        Fy_.resize(q, k);
        Fy_f_.resize(q, k);
        for (Index c0 = 0; c0 < k; c0 += kColumnBlock) {
          const Index w = std::min(kColumnBlock, k - c0);
          if (!Gy.middleCols(c0, w).allFinite()) check_finite("FusedAlternation::set: G_y", Gy);  // throws
          Fy_.middleCols(c0, w) = C0_.middleCols(c0, w) + Gy.middleCols(c0, w);
          detail::blas_gemm(false, false, -1.0, GzT, phase1.R_.middleCols(c0, w), 1.0, Fy_.middleCols(c0, w));
          Fy_f_.middleCols(c0, w) = Fy_.middleCols(c0, w).template cast<float>();
        }
      }
      fast = true;
    }
  }
  if (!fast) {
    base_ready_ = false;
    check_finite("FusedAlternation::set: G_z", Gz);
    check_finite("FusedAlternation::set: G_y", Gy);
    Fy_ = Gy;
    if constexpr (std::is_same_v<Scalar, double>) {
      Fb_.resize(q, phase1.m());
      detail::blas_gemm(false, false, 1.0, Gz, phase1.Mb(), 0.0, Fb_);
      detail::blas_gemm(false, false, 1.0, Gz, phase1.MY(), 1.0, Fy_);
    } else {
      Fb_.noalias() = Gz * phase1.Mb();
      Fy_.noalias() += Gz * phase1.MY();
    }
    Fy_f_ = Fy_.template cast<float>();
  }
  gb_.resize(q);
  g_.resize(q);
  gf_.resize(q);
  yf_.resize(k);
  ready_ = true;
}

template <typename Scalar>
void FusedAlternation<Scalar>::keep_inputs(const Matrix<Scalar>& Gz, const Matrix<Scalar>& Gy) {
  inputs_ready_ = false;
  if (!same_matrix(Gz_, Gz)) {
    prep_.reset();
    Gz_ = Gz;
  }
  if (!same_matrix(Gy_, Gy)) {
    base_ready_ = false;
    Gy_ = Gy;
  }
  inputs_ready_ = true;
}

template <typename Scalar>
void FusedAlternation<Scalar>::form_c0(const FixedCoordinateSolver<Scalar>& phase1, const Matrix<Scalar>& Gz) {
  if constexpr (std::is_same_v<Scalar, double>) {
    if (prep_ == phase1.prep_) return;
    // C0 = G_z·P0, once per (Phase 1 preparation, G_z).
    prep_.reset();
    base_ready_ = false;
    check_finite("FusedAlternation: G_z", Gz);
    C0_.resize(Gz.rows(), phase1.prep_->P0.cols());
    detail::blas_gemm(false, false, 1.0, Gz, phase1.prep_->P0, 0.0, C0_);
    Gz_f_.resize(0, 0);
    prep_ = phase1.prep_;
  } else {
    (void)phase1, (void)Gz;
  }
}

template <typename Scalar>
void FusedAlternation<Scalar>::form_gz_float(const Matrix<Scalar>& Gz) {
  // form_c0 empties it whenever G_z or Phase 1's preparation changes.
  if (Gz_f_.rows() != Gz.rows() || Gz_f_.cols() != Gz.cols()) Gz_f_ = Gz.template cast<float>();
}

template <typename Scalar>
void FusedAlternation<Scalar>::prepare(const FixedCoordinateSolver<Scalar>& phase1, const Matrix<Scalar>& Gz,
                                       const Matrix<Scalar>& Gy, FusedPrecision precision) {
  check_size("FusedAlternation::prepare: G_y rows (as G_z)", Gz.rows(), Gy.rows());
  if (phase1.prep_) {
    check_size("FusedAlternation::prepare: G_z columns (d)", phase1.prep_->G.rows(), Gz.cols());
    check_size("FusedAlternation::prepare: G_y columns (k)", phase1.prep_->G.cols(), Gy.cols());
  }
  check_finite("FusedAlternation::prepare: G_z", Gz);
  check_finite("FusedAlternation::prepare: G_y", Gy);
  ready_ = false;
  keep_inputs(Gz, Gy);
  if constexpr (std::is_same_v<Scalar, double>) {
    if (phase1.prep_) {
      const detail::ScopedBlasThreads blas(1);
      form_c0(phase1, Gz_);
      if (precision == FusedPrecision::Float) form_gz_float(Gz_);
    }
  } else {
    (void)precision;
  }
}

template <typename Scalar>
void FusedAlternation<Scalar>::round_product(const Scalar* y, const float* yf, Index r0, Index r1, double* ry,
                                             float* ryf) {
  const Index rows = r1 - r0, mu = R_.rows();
  if (yf != nullptr) {
    // Mixed precision: the q×k product in float (twice the SIMD width of
    // double), accumulated onto g in double; the factored form's correction
    // −(G_z·T)·(R·y) in float too (its error is of the same order).
    std::fill(gf_.data() + r0, gf_.data() + r1, 0.0f);
    detail::gemv_add(Fy_f_.data() + r0, rows, Fy_f_.cols(), Fy_f_.outerStride(), yf, gf_.data() + r0);
    if (factored_) {
      std::fill(ryf, ryf + mu, 0.0f);
      detail::gemv_add(R_f_.data(), mu, R_f_.cols(), R_f_.outerStride(), yf, ryf);
      for (Index i = 0; i < mu; ++i) ryf[i] = -ryf[i];
      detail::gemv_add(GzT_f_.data() + r0, rows, mu, GzT_f_.outerStride(), ryf, gf_.data() + r0);
    }
    g_.segment(r0, rows) = gb_.segment(r0, rows) + gf_.segment(r0, rows).template cast<Scalar>();
    return;
  }
  g_.segment(r0, rows) = gb_.segment(r0, rows);
  detail::gemv_add(Fy_.data() + r0, rows, Fy_.cols(), Fy_.outerStride(), y, g_.data() + r0);
  if constexpr (std::is_same_v<Scalar, double>) {
    if (factored_) {
      // g −= (G_z·T)·(R·y), in double.
      std::fill(ry, ry + mu, 0.0);
      detail::gemv_add(R_.data(), mu, R_.cols(), R_.outerStride(), y, ry);
      for (Index i = 0; i < mu; ++i) ry[i] = -ry[i];
      detail::gemv_add(GzT_.data() + r0, rows, mu, GzT_.outerStride(), ry, g_.data() + r0);
    }
  }
}

template <typename Scalar>
AlternatingSummary FusedAlternation<Scalar>::run(const FixedCoordinateSolver<Scalar>& phase1,
                                                 InputProjection<Scalar>& projection,
                                                 const Eigen::Ref<const Vector<Scalar>>& b,
                                                 const AlternatingOptions& options, Eigen::Ref<Vector<Scalar>> z,
                                                 Eigen::Ref<Vector<Scalar>> y) {
  if (!ready_) throw std::invalid_argument("FusedAlternation::run: not set (call set after set_constraints or prepare)");
  check_size("FusedAlternation::run: b (m)", Fb_.cols(), b.size());
  check_size("FusedAlternation::run: y (k)", Fy_.cols(), y.size());
  check_size("FusedAlternation::run: z (d)", phase1.d(), z.size());
  assert(options.is_valid(nullptr));
  if (float_set_ && !options.float_products) {
    throw std::invalid_argument(
        "FusedAlternation::run: set with FusedPrecision::Float needs float rounds "
        "(AlternatingOptions::float_products)");
  }
  AlternatingSummary summary;
  // The products go through the run-time dispatched AVX2/FMA kernels
  // (simd_kernels.h) when the CPU has them.
  detail::gemv(Fb_, b.data(), gb_.data(), false);
  const Index block = projection.block_size();
  const int threads = options.threads > 0 ? options.threads : omp_get_max_threads();
  if (threads > 1 && block > 0 && !omp_in_parallel() && Fy_.rows() == Fy_.cols() && Fy_.rows() % block == 0 &&
      Fy_.size() >= options.parallel_min_entries && Fy_.rows() / block >= 2) {
    summary = run_parallel(projection, options, std::min<Index>(threads, Fy_.rows() / block), block, y);
    phase1.solve(b, y, z);
    summary.status = Status::Success;
    return summary;
  }
  for (int it = 0; it < options.iterations; ++it) {
    if (options.float_products) yf_ = y.template cast<float>();
    round_product(y.data(), options.float_products ? yf_.data() : nullptr, 0, Fy_.rows(), ry_.data(), ryf_.data());
    summary.last_change = projection.project(g_, y);
    summary.iterations = it + 1;
    if (options.tolerance > 0 &&
        summary.last_change <= options.tolerance * std::max(1.0, static_cast<double>(y.norm())))
      break;
  }
  phase1.solve(b, y, z);
  summary.status = Status::Success;
  return summary;
}

template <typename Scalar>
AlternatingSummary FusedAlternation<Scalar>::run_parallel(InputProjection<Scalar>& projection,
                                                          const AlternatingOptions& options, Index threads,
                                                          Index block, Eigen::Ref<Vector<Scalar>> y) {
  const Index q = Fy_.rows(), blocks = q / block;
  const bool use_float = options.float_products;
  // The y the products read, double-buffered by round parity (round r reads
  // column r mod 2, its Phase 2 writes the other).
  y2_.resize(q, 2);
  y2_.col(0) = y;
  if (use_float) {
    yf2_.resize(q, 2);
    yf2_.col(0) = y.template cast<float>();
  }
  // Per-thread Σ‖Δy_j‖² and ‖y_j‖², by round parity: read after the round's
  // barrier, next written two rounds later (after the next barrier).
  constexpr int kMaxThreads = 64;
  threads = std::min<Index>(threads, kMaxThreads);
  double change2[2][kMaxThreads] = {}, norm2[2][kMaxThreads] = {};
  ry_threads_.resize(R_.rows(), threads);  // these allocate on the first call only
  ryf_threads_.resize(R_.rows(), threads);
  int rounds = 0;
  double last = 0.0;
#pragma omp parallel num_threads(static_cast<int>(threads))
  {
    const Index t = omp_get_thread_num(), nt = omp_get_num_threads();
    const Index r0 = block * (blocks * t / nt), r1 = block * (blocks * (t + 1) / nt), rows = r1 - r0;
    double* ry = ry_threads_.col(t).data();  // factored form: this thread's R·y
    float* ryf = ryf_threads_.col(t).data();
    for (int it = 0; it < options.iterations; ++it) {
      const int cur = it % 2, next = 1 - cur;
      round_product(y2_.col(cur).data(), use_float ? yf2_.col(cur).data() : nullptr, r0, r1, ry, ryf);
      change2[cur][t] = projection.project_blocks(g_, y, r0 / block, r1 / block);
      norm2[cur][t] = static_cast<double>(y.segment(r0, rows).squaredNorm());
      y2_.col(next).segment(r0, rows) = y.segment(r0, rows);
      if (use_float) yf2_.col(next).segment(r0, rows) = y.segment(r0, rows).template cast<float>();
#pragma omp barrier
      // Only this round's sums are read here: y itself may already be
      // changing in another thread's next round.
      double total = 0.0, ynorm2 = 0.0;
      for (Index s = 0; s < nt; ++s) {
        total += change2[cur][s];
        ynorm2 += norm2[cur][s];
      }
      const double change = std::sqrt(total);
      if (t == 0) {
        rounds = it + 1;
        last = change;
      }
      // Every thread takes the same decision from the same sums.
      if (options.tolerance > 0 && change <= options.tolerance * std::max(1.0, std::sqrt(ynorm2))) break;
    }
  }
  AlternatingSummary summary;
  summary.iterations = rounds;
  summary.last_change = last;
  return summary;
}

template class FusedAlternation<double>;
template class FixedCoordinateSolver<double>;

}  // namespace qpreduce
