// Quotient equivalence and Theorem 4.10 (Section 4): the factor H = LᵀL, the
// whitened design, the closed forms of Prop. 4.6/4.7/4.9 against KKT solves,
// and the error bound on seeded trials (generators::theorem_problem).
#include <catch2/catch.hpp>

#include "qpreduce/problems/generators.h"
#include "qpreduce/quotient.h"

#include <Eigen/Dense>
#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>
#include <string>
#include <vector>

using namespace qpreduce;
namespace gen = qpreduce::generators;

namespace {

constexpr double kEps = std::numeric_limits<double>::epsilon();

// M·M⁺, the orthogonal projector onto the column space of M, with the
// pseudo-inverse of the paper's formulas. Singular values below
// 1e-10·reference count as zero: a column of D̂ = (L⁺)ᵀD is pure round-off
// when that column of D lies in ker H (the constants, for a grid Laplacian).
Matrix<double> projector_by_pinv(const Matrix<double>& M, double reference) {
  if (M.cols() == 0) return Matrix<double>::Zero(M.rows(), M.rows());
  Eigen::JacobiSVD<Matrix<double>> svd(M, Eigen::ComputeThinU | Eigen::ComputeThinV);
  const Index rank = (svd.singularValues().array() > 1e-10 * reference).count();
  const Matrix<double> U = svd.matrixU().leftCols(rank);
  return U * U.transpose();
}

// Dense KKT solve of min ½‖X̂‖² − q̂ᵀX̂ s.t. (QᵀÂ)ᵀu = b̂ over X̂ = Q·u
// (Q = I: Eq. 27; Q an orthonormal basis of Span(Ĉ) + Span(D̂): Eq. 35).
Vector<double> whitened_kkt_solve(const Matrix<double>& Q, const Matrix<double>& A_hat, const Vector<double>& q_hat,
                                  const Vector<double>& b_hat) {
  const Index s = Q.cols(), m = A_hat.cols();
  const Matrix<double> QA = Q.transpose() * A_hat;
  Matrix<double> K = Matrix<double>::Zero(s + m, s + m);
  K.topLeftCorner(s, s).setIdentity();
  K.topRightCorner(s, m) = QA;
  K.bottomLeftCorner(m, s) = QA.transpose();
  Vector<double> rhs(s + m);
  rhs << Q.transpose() * q_hat, b_hat;
  return Q * K.fullPivLu().solve(rhs).head(s);
}

std::string fmt_expected(Index expected, Index got) { return fmt::format("expected {}, got {}", expected, got); }

std::string fmt_trial(gen::TheoremFamily family, Index size, double eps, std::uint64_t seed) {
  return fmt::format("theorem_problem({}, {}, {}, {})", gen::to_string(family), size, eps, seed);
}

std::string message_of(const std::function<void()>& f) {
  try {
    f();
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
  return "no exception";
}

// Sizes used by the trial sweep: small enough for the ASan build.
Index sweep_size(int group) { return 30 + (group * 13) % 70; }

const std::vector<double> kSweepEpsilons = {0.0, 1e-7, 1e-6, 1e-5, 1e-4, 1e-3, 1e-2, 3e-2, 0.1, 0.3};

}  // namespace

TEST_CASE("factor_psd: rank-revealing H = LᵀL with L·L⁺ = I_r", "[quotient][factor]") {
  SECTION("dense PSD with a null space") {
    const Index n = 40, nullity = 3;
    Matrix<double> K_true;
    const SparseMatrix<double> H = gen::random_psd_with_condition(n, nullity, 1e3, 3, &K_true);
    PsdFactor f;
    const FactorSummary s = factor_psd(H, {}, &f);
    INFO(s.message);
    REQUIRE(s.ok());
    CHECK(s.rank == n - nullity);
    CHECK(s.nullity == nullity);
    CHECK(f.L.rows() == n - nullity);
    CHECK(f.L.cols() == n);
    CHECK(f.L_pinv.rows() == n);
    CHECK(s.residual < 100 * n * kEps);
    const Index r = f.rank();
    CHECK((f.L * f.L_pinv - Matrix<double>::Identity(r, r)).norm() < 100 * n * kEps);
    // L⁺L + KKᵀ = I, and K spans the true kernel.
    const Matrix<double> P = f.L_pinv * f.L;
    CHECK((P + f.kernel * f.kernel.transpose() - Matrix<double>::Identity(n, n)).norm() < 100 * n * kEps);
    CHECK((f.L * K_true).norm() < 100 * n * kEps * f.L.norm());
    // d_H = ‖L(x − y)‖ = sqrt((x − y)ᵀH(x − y)); a kernel shift does not change it.
    const Vector<double> x = gen::gaussian_vector(n, 4), y = gen::gaussian_vector(n, 5);
    CHECK(f.distance(x, y) == Approx(h_distance(H, x, y)).epsilon(1e-12));
    const Vector<double> shift = K_true * gen::gaussian_vector(nullity, 6);
    CHECK(f.distance(x + shift, y) == Approx(f.distance(x, y)).epsilon(1e-12));
    CHECK(f.null_part(shift).isApprox(shift, 1e-12));
  }
  SECTION("grid Laplacian: the kernel is the constants") {
    const SparseMatrix<double> H = gen::grid_laplacian_2d(7, 6);
    PsdFactor f;
    REQUIRE(factor_psd(H, {}, &f).ok());
    REQUIRE(f.nullity() == 1);
    const Vector<double> ones = Vector<double>::Ones(42) / std::sqrt(42.0);
    CHECK(std::abs(std::abs(f.kernel.col(0).dot(ones)) - 1.0) < 1e-12);
  }
  SECTION("positive definite: no kernel") {
    PsdFactor f;
    const FactorSummary s = factor_psd(gen::grid_laplacian_3d(3, 4, 3, 0.1), {}, &f);
    REQUIRE(s.ok());
    CHECK(s.nullity == 0);
    CHECK(f.kernel.cols() == 0);
  }
}

TEST_CASE("bad input: std::invalid_argument or a failed status naming the problem", "[quotient][errors]") {
  const gen::TheoremTrial t = gen::theorem_problem(gen::TheoremFamily::Grid2d, 36, 0.01, 9);
  PsdFactor f;

  SECTION("non-square H") {
    const Matrix<double> H = Matrix<double>::Identity(5, 4);
    CHECK_THAT(message_of([&] { factor_psd(H, {}, &f); }), Catch::Contains("expected 5, got 4"));
  }
  SECTION("NaN in H") {
    SparseMatrix<double> H = t.H;
    H.coeffRef(2, 2) = std::numeric_limits<double>::quiet_NaN();
    CHECK_THAT(message_of([&] { factor_psd(H, {}, &f); }), Catch::Contains("NaN"));
    CHECK_THAT(message_of([&] { check_theorem(H, t.C, t.D, t.A, t.b, t.q); }), Catch::Contains("NaN"));
  }
  SECTION("asymmetric H") {
    SparseMatrix<double> H = t.H;
    H.coeffRef(0, 1) += 0.25;
    CHECK_THAT(message_of([&] { factor_psd(H, {}, &f); }), Catch::Contains("not symmetric"));
    CHECK_THAT(message_of([&] { factor_psd(Matrix<double>(H), {}, &f); }), Catch::Contains("not symmetric"));
  }
  SECTION("indefinite H: a status, never a crash or NaN") {
    SparseMatrix<double> H = t.H;
    H.coeffRef(4, 4) -= 10.0;  // symmetric, now with a negative eigenvalue
    const FactorSummary s = factor_psd(H, {}, &f);
    CHECK(s.status == Status::IndefiniteH);
    CHECK_THAT(s.message, Catch::Contains("indefinite") && Catch::Contains("λ_min"));
    CHECK(f.L.size() == 0);
    const TheoremCheck c = check_theorem(H, t.C, t.D, t.A, t.b, t.q);
    CHECK(c.status == TheoremStatus::IndefiniteH);
    CHECK_THAT(c.message, Catch::Contains("indefinite"));
    CHECK(!std::isnan(c.bound.bound));
  }
  SECTION("size mismatches in the design and the demand") {
    TheoremChecker checker;
    const SparseMatrix<double> Cbad(t.n() - 1, 3);
    CHECK_THAT(message_of([&] { checker.precompute(t.H, Cbad, t.D); }),
               Catch::Contains("C rows") && Catch::Contains(fmt_expected(t.n(), t.n() - 1)));
    CHECK_THAT(message_of([&] { checker.check(t.A, t.b, t.q); }), Catch::Contains("precompute"));
    REQUIRE(checker.precompute(t.H, t.C, t.D).ok());
    const Vector<double> bbad = Vector<double>::Zero(t.m() + 1);
    CHECK_THAT(message_of([&] { checker.check(t.A, bbad, t.q); }), Catch::Contains("b size"));
    const SparseMatrix<double> Abad(t.n() + 2, t.m());
    CHECK_THAT(message_of([&] { checker.check(Abad, t.b, t.q); }), Catch::Contains("A rows"));
    Vector<double> qnan = t.q;
    qnan(0) = std::numeric_limits<double>::quiet_NaN();
    CHECK_THAT(message_of([&] { checker.check(t.A, t.b, qnan); }), Catch::Contains("NaN"));
  }
  SECTION("invalid options") {
    QuotientOptions o;
    o.rank_tolerance = 0.0;
    CHECK_THAT(message_of([&] { factor_psd(t.H, o, &f); }), Catch::Contains("rank_tolerance"));
  }
  SECTION("rank-deficient A: the exact solve reports it") {
    Matrix<double> A(t.A);
    Matrix<double> A2(A.rows(), A.cols() + 1);
    A2 << A, A.col(0);  // a repeated column
    Vector<double> b2(t.m() + 1);
    b2 << t.b, t.b(0);
    const TheoremCheck c = check_theorem(t.H, t.C, t.D, A2.sparseView(), b2, t.q);
    CHECK(c.status == TheoremStatus::SolveFailed);
    CHECK_THAT(c.message, Catch::Contains("full column rank"));
  }
}

TEST_CASE("theorem_bound: failed hypotheses give a status and +inf, never NaN", "[quotient][errors]") {
  // r = 6, design Span(e0, e1), Â inside Span(e2..e5).
  WhitenedDesign design;
  design.basis = Matrix<double>::Identity(6, 2);
  design.I_hat = design.basis * design.basis.transpose();
  CompanionDemand demand;
  demand.q_hat = gen::gaussian_vector(6, 1);
  demand.b_hat = gen::gaussian_vector(2, 2);

  SECTION("ÎÂ = 0: ρ = 1, the theorem does not apply") {
    demand.A_hat = Matrix<double>::Zero(6, 2);
    demand.A_hat.bottomRows(4) = gen::gaussian_matrix(4, 2, 3);
    const TheoremBound t = theorem_bound(design, demand);
    CHECK(t.status == TheoremStatus::DoesNotApply);
    CHECK_THAT(t.message, Catch::Contains("does not apply"));
    CHECK(t.rho == Approx(1.0));
    CHECK(std::isinf(t.bound));
    CHECK(std::isinf(t.refined_bound));  // Â_p = 0 is rank deficient too
    CHECK(!std::isnan(t.Delta));
    Vector<double> X;
    CHECK_FALSE(subspace_companion_solution(design, demand, &X));
  }
  SECTION("Â with dependent columns") {
    demand.A_hat = Matrix<double>::Zero(6, 2);
    demand.A_hat.col(0) = gen::gaussian_vector(6, 4);
    demand.A_hat.col(1) = 2.0 * demand.A_hat.col(0);
    const TheoremBound t = theorem_bound(design, demand);
    CHECK(t.status == TheoremStatus::RankDeficientA);
    CHECK_THAT(t.message, Catch::Contains("rank 1 < m = 2"));
    CHECK(std::isinf(t.bound));
    Vector<double> X;
    CHECK_FALSE(companion_solution(demand, &X));
  }
}

TEST_CASE("whitened design: Prop. 4.7 and the projector of Prop. 4.9", "[quotient][design]") {
  for (gen::TheoremFamily family : gen::theorem_families()) {
    CAPTURE(gen::to_string(family));
    const gen::TheoremTrial t = gen::theorem_problem(family, 64, 0.0, 21);
    TheoremChecker checker;
    const TheoremSetupSummary s = checker.precompute(t.H, t.C, t.D);
    INFO(s.message);
    REQUIRE(s.ok());
    const PsdFactor& f = checker.factor();
    const WhitenedDesign& w = checker.design();
    const Index r = f.rank(), d = t.d(), k = t.k(), nullity = f.nullity();
    const double tol = 1e3 * r * kEps;
    // ‖(L⁺)ᵀ‖ = 1/√λ_min: the scale of round-off in whitened data.
    const double whiten_norm = 1.0 / std::sqrt(s.factor.lambda_min_kept);

    // Î: symmetric, idempotent, fixes Ĉ and D̂, equals ÛD̂(ÛD̂)⁺ + ĈĈ⁺.
    CHECK((w.I_hat - w.I_hat.transpose()).norm() < tol);
    CHECK((w.I_hat * w.I_hat - w.I_hat).norm() < tol);
    CHECK((w.I_hat * w.C_hat - w.C_hat).norm() < tol * whiten_norm * Matrix<double>(t.C).norm());
    CHECK((w.I_hat * w.D_hat - w.D_hat).norm() < tol * whiten_norm * Matrix<double>(t.D).norm());
    Matrix<double> CD(r, d + k);
    CD << w.C_hat, w.D_hat;
    const double scale = CD.norm();
    const Matrix<double> formula = projector_by_pinv(w.UD_hat, scale) + projector_by_pinv(w.C_hat, scale);
    CHECK((w.I_hat - formula).norm() < 1e-8);
    CHECK(w.U_hat.isApprox(Matrix<double>::Identity(r, r) - projector_by_pinv(w.C_hat, scale), 1e-10));
    // A column of D in ker H whitens to zero: the rank drops by
    // dim((Span(C) + Span(D)) ∩ ker H) (1 for the grids, whose D holds the constants).
    const Index lost = (family == gen::TheoremFamily::Grid2d || family == gen::TheoremFamily::Grid3d) ? 1 : 0;
    CHECK(w.rank == d + k - lost);
    // Grids: ker H = constants ⊆ Span(D); dense PSD: a random kernel is not in the design.
    CHECK(w.kernel_in_design() == (family != gen::TheoremFamily::DensePsd));

    // Eq. 29 columns: ĈᵀN̂ = I, ĈᵀÛD̂ = 0 (Ĉ has full column rank here).
    REQUIRE(w.rank_C_hat == d);
    CHECK((w.C_hat.transpose() * w.N_hat - Matrix<double>::Identity(d, d)).norm() < 1e-9);
    CHECK((w.C_hat.transpose() * w.UD_hat).norm() < 1e-9 * w.D_hat.norm() * w.C_hat.norm());

    // Prop. 4.5/4.7 against the engine's subspace: L·N = N̂(I − CᵀKKᵀN),
    // L·UD = ÛD̂ − N̂·CᵀKKᵀUD; with H PD (K empty) simply L·N = N̂, L·UD = ÛD̂.
    const VariationalSubspace<double>& sub = checker.solver().subspace();
    const Matrix<double> C(t.C);
    const Matrix<double> CtKKt = C.transpose() * f.kernel * f.kernel.transpose();
    const Matrix<double> LN = f.L * sub.N, LUD = f.L * sub.UD;
    const Matrix<double> N_rel = w.N_hat * (Matrix<double>::Identity(d, d) - CtKKt * sub.N);
    const Matrix<double> UD_rel = w.UD_hat - w.N_hat * (CtKKt * sub.UD);
    CHECK((LN - N_rel).norm() <= 1e-9 * (1 + LN.norm()));
    CHECK((LUD - UD_rel).norm() <= 1e-9 * (1 + LUD.norm()));
    if (t.kernel.cols() == 0) {
      CHECK((LN - w.N_hat).norm() <= 1e-9 * (1 + LN.norm()));
      CHECK((LUD - w.UD_hat).norm() <= 1e-9 * (1 + LUD.norm()));
    } else {
      // ker H ⊆ Span(N), so the engine's L·Span([N UD]) has dimension
      // d + k − ν, inside Span(Ĉ) + Span(D̂).
      Matrix<double> LB(r, d + k);
      LB << LN, LUD;
      const auto sv = Eigen::JacobiSVD<Matrix<double>>(LB).singularValues();
      const Index rank = (sv.array() > 1e-9 * sv(0)).count();
      CHECK(rank == d + k - nullity);
      CHECK((w.I_hat * LB - LB).norm() <= 1e-9 * LB.norm());
    }
  }
}

TEST_CASE("closed forms (Prop. 4.6, 4.9) agree with KKT solves", "[quotient][closed-form]") {
  for (gen::TheoremFamily family : gen::theorem_families()) {
    for (double eps : {0.0, 1e-3, 0.1}) {
      CAPTURE(gen::to_string(family), eps);
      const gen::TheoremTrial t = gen::theorem_problem(family, 50, eps, 33);
      TheoremSolutions sol;
      const TheoremCheck c = check_theorem(t.H, t.C, t.D, t.A, t.b, t.q, {}, &sol);
      INFO(c.message);
      REQUIRE(c.status == TheoremStatus::Applies);
      const CompanionDemand& dm = sol.demand;
      const Index r = dm.A_hat.rows();
      // Eq. 30 = KKT of Eq. 27 = L·X_min (Theorem 4.3 / Prop. 4.4).
      const Vector<double> kkt = whitened_kkt_solve(Matrix<double>::Identity(r, r), dm.A_hat, dm.q_hat, dm.b_hat);
      const double scale = 1.0 + sol.X_hat_min.norm();
      CHECK((sol.X_hat_min - kkt).norm() <= 1e-10 * scale);
      CHECK(c.closed_form_gap <= 1e-10 * scale);
      // Eq. 35 = KKT of Eq. 27 restricted to Span(Ĉ) + Span(D̂).
      TheoremChecker checker;
      REQUIRE(checker.precompute(t.H, t.C, t.D).ok());
      const Vector<double> kkt_sub = whitened_kkt_solve(checker.design().basis, dm.A_hat, dm.q_hat, dm.b_hat);
      REQUIRE(sol.X_hat_star.size() == r);
      CHECK((sol.X_hat_star - kkt_sub).norm() <= 1e-10 * scale);
      // The bound's terms are what Eq. 39 says they are.
      const TheoremBound& b = c.bound;
      CHECK(b.beta1 == Approx((2 - b.rho) / (1 - b.rho)));
      CHECK(b.beta2 == Approx(1 + b.omega / (1 - b.rho)));
      CHECK(b.Delta == Approx(b.beta1 * b.norm_b_hat * b.norm_A_pinv * b.norm_A_pinv +
                              b.beta2 * b.norm_q_hat * b.norm_A_pinv));
      CHECK(b.bound == Approx(b.q_residual + b.Delta * b.A_residual).margin(1e-300));
      CHECK(b.refined_bound <= b.bound * (1 + 1e-12));
    }
  }
}

TEST_CASE("ε = 0: the reduced solution reproduces the exact one and every bound term vanishes",
          "[quotient][exact]") {
  for (gen::TheoremFamily family : gen::theorem_families()) {
    for (std::uint64_t seed = 1; seed <= 6; ++seed) {
      const Index size = 30 + 25 * static_cast<Index>(seed);
      CAPTURE(gen::to_string(family), seed, size);
      const gen::TheoremTrial t = gen::theorem_problem(family, size, 0.0, seed);
      const TheoremCheck c = check_theorem(t.H, t.C, t.D, t.A, t.b, t.q);
      INFO(c.message);
      REQUIRE(c.status == TheoremStatus::Applies);
      CHECK(c.practical_rel_error <= 1e-10);
      CHECK(c.practical_error <= 1e-10 * c.exact_norm);
      CHECK(c.theorem_error <= 1e-10 * c.exact_norm);
      // Round-off of whitened data is relative to ‖(L⁺)ᵀ‖·‖data‖ (a column of D
      // in ker H whitens to pure round-off).
      const double r = static_cast<double>(c.bound.r);
      PsdFactor f;
      const FactorSummary fs = factor_psd(t.H, {}, &f);
      const double whiten_norm = 1.0 / std::sqrt(fs.lambda_min_kept);
      CHECK(c.bound.q_residual <= 100 * r * kEps * whiten_norm * t.q.norm());
      CHECK(c.bound.A_residual <= 100 * r * kEps * whiten_norm * Matrix<double>(t.A).norm());
      CHECK(c.bound.rho <= 100 * r * kEps * c.bound.omega);
      CHECK(c.bound.bound <= 1e-10 * c.exact_norm);
    }
  }
}

TEST_CASE("Theorem 4.10 holds on 2,000+ seeded trials across families and ε", "[quotient][bound]") {
  struct Worst {
    double ratio = 0.0;
    std::string where;
  };
  int trials = 0, applies = 0, failed = 0, practical_violations = 0, theorem_violations = 0,
      refined_violations = 0, pd_trials = 0, covered_trials = 0, galerkin_violations = 0;
  Worst worst_practical, worst_theorem, worst_refined, worst_pd_gap;
  std::string first_failure;
  const std::vector<gen::TheoremFamily> families = gen::theorem_families();
  const int groups = 204;  // × 10 values of ε = 2,040 trials
  for (int g = 0; g < groups; ++g) {
    const gen::TheoremFamily family = families[static_cast<size_t>(g) % families.size()];
    gen::TheoremTrial t = gen::theorem_problem(family, sweep_size(g), 0.0, 5000 + static_cast<std::uint64_t>(g));
    TheoremChecker checker;
    const TheoremSetupSummary setup = checker.precompute(t.H, t.C, t.D);
    if (!setup.ok()) {
      failed += static_cast<int>(kSweepEpsilons.size());
      if (first_failure.empty()) first_failure = setup.message;
      continue;
    }
    for (double eps : kSweepEpsilons) {
      t.set_epsilon(eps);
      const TheoremCheck c = checker.check(t.A, t.b, t.q);
      ++trials;
      const std::string where = fmt_trial(family, t.size, eps, t.seed);
      if (c.status == TheoremStatus::SolveFailed || c.status == TheoremStatus::RankDeficientA) {
        ++failed;
        if (first_failure.empty()) first_failure = where + ": " + c.message;
        continue;
      }
      if (c.status != TheoremStatus::Applies) continue;
      ++applies;
      practical_violations += c.practical_violation();
      theorem_violations += c.theorem_violation();
      refined_violations += c.theorem_error > c.bound.refined_bound + c.slack;
      auto track = [&](Worst& w, double value) {
        if (value > w.ratio) w = {value, where};
      };
      if (eps > 0.0) {  // at ε = 0 both sides are round-off; the slack decides
        track(worst_practical, c.practical_error / c.bound.bound);
        track(worst_theorem, c.theorem_error / c.bound.bound);
        track(worst_refined, c.theorem_error / c.bound.refined_bound);
      }
      if (c.practical_covered) {
        // ker H ⊆ Span(C) + Span(D): X* is the d_H-best feasible point of the
        // subspace, which contains the lift of Eq. 35's solution.
        ++covered_trials;
        galerkin_violations += c.practical_error > c.theorem_error + c.slack;
      }
      if (t.kernel.cols() == 0) {
        // H PD: the engine's answer is the theorem's reduced solution, L·X* = X̂*_min.
        ++pd_trials;
        track(worst_pd_gap, c.practical_gap / (c.slack + 1e-10 * c.exact_norm));
      }
    }
  }
  INFO("first failure: " << first_failure);
  INFO("worst error/bound (engine X*): " << worst_practical.ratio << " at " << worst_practical.where);
  INFO("worst error/bound (Eq. 35): " << worst_theorem.ratio << " at " << worst_theorem.where);
  INFO("worst error/refined bound (Eq. 35): " << worst_refined.ratio << " at " << worst_refined.where);
  INFO("worst PD gap / tolerance: " << worst_pd_gap.ratio << " at " << worst_pd_gap.where);
  CHECK(trials >= 2000);
  CHECK(failed == 0);
  CHECK(applies >= trials * 8 / 10);
  CHECK(practical_violations == 0);
  CHECK(theorem_violations == 0);
  CHECK(refined_violations == 0);
  CHECK(pd_trials > 0);
  CHECK(worst_pd_gap.ratio <= 1.0);
  CHECK(covered_trials > pd_trials);  // the ridge-free grids are covered too
  CHECK(galerkin_violations == 0);
}

TEST_CASE("ker H outside the design: the bound covers Eq. 35, not the engine's answer", "[quotient][kernel]") {
  // Dense PSD H whose kernel K is not in Span(C) + Span(D). Perturb the demand
  // only along ker H: the whitened data do not move (Â = Ĉ·A_c, q̂ = D̂·Y), so
  // the bound stays at round-off, and so does the error of Eq. 35; the
  // engine's X* cannot follow (its subspace lacks those directions).
  const gen::TheoremTrial t = gen::theorem_problem(gen::TheoremFamily::DensePsd, 64, 0.0, 3);
  REQUIRE(t.kernel.cols() > 0);
  const Matrix<double> CAc = t.C * t.A_c;
  Matrix<double> E = t.kernel * gen::gaussian_matrix(t.kernel.cols(), t.m(), 99);
  E *= CAc.norm() / E.norm();
  const double eps = 0.01;
  const SparseMatrix<double> A = (CAc + eps * E).sparseView();
  const Vector<double> q =
      t.q + eps * t.q.norm() * (t.kernel * gen::gaussian_vector(t.kernel.cols(), 98)).normalized();

  TheoremChecker checker;
  REQUIRE(checker.precompute(t.H, t.C, t.D).ok());
  CHECK_FALSE(checker.design().kernel_in_design());
  CHECK(checker.design().kernel_angle > 0.1);
  for (int which = 0; which < 2; ++which) {
    CAPTURE(which);  // 0: A perturbed along ker H, 1: q perturbed along ker H
    const TheoremCheck c = which == 0 ? checker.check(A, t.b, t.q) : checker.check(t.A, t.b, q);
    REQUIRE(c.status == TheoremStatus::Applies);
    CHECK_FALSE(c.practical_covered);
    CHECK(c.bound.bound <= 1e-10 * c.exact_norm);
    CHECK(c.theorem_error <= c.bound.bound + c.slack);  // the theorem holds …
    CHECK(c.practical_violation());                      // … but not for X*
    CHECK(c.practical_error > 1e-4 * c.exact_norm);
  }

  // Remedy: put a basis of ker H into D (or C). Then X* is covered again.
  Matrix<double> D2(t.n(), t.k() + t.kernel.cols());
  D2 << Matrix<double>(t.D), t.kernel;
  TheoremChecker fixed;
  REQUIRE(fixed.precompute(t.H, t.C, D2.sparseView()).ok());
  CHECK(fixed.design().kernel_in_design());
  for (int which = 0; which < 2; ++which) {
    CAPTURE(which);
    const TheoremCheck c = which == 0 ? fixed.check(A, t.b, t.q) : fixed.check(t.A, t.b, q);
    REQUIRE(c.status == TheoremStatus::Applies);
    CHECK(c.practical_covered);
    CHECK_FALSE(c.practical_violation());
    CHECK(c.practical_error <= c.theorem_error + c.slack);
  }
}

TEST_CASE("the error falls linearly with ε", "[quotient][rate]") {
  const std::vector<double> eps = {1e-7, 1e-6, 1e-5, 1e-4};
  for (gen::TheoremFamily family : gen::theorem_families()) {
    for (std::uint64_t seed : {7u, 8u}) {
      CAPTURE(gen::to_string(family), seed);
      gen::TheoremTrial t = gen::theorem_problem(family, 60, 0.0, seed);
      TheoremChecker checker;
      REQUIRE(checker.precompute(t.H, t.C, t.D).ok());
      std::vector<double> x, y_practical, y_theorem, y_bound;
      for (double e : eps) {
        t.set_epsilon(e);
        const TheoremCheck c = checker.check(t.A, t.b, t.q);
        REQUIRE(c.status == TheoremStatus::Applies);
        x.push_back(std::log10(e));
        y_practical.push_back(std::log10(c.practical_error));
        y_theorem.push_back(std::log10(c.theorem_error));
        y_bound.push_back(std::log10(c.bound.bound));
      }
      // Least-squares slope on the log-log points.
      auto slope = [&](const std::vector<double>& y) {
        const double n = static_cast<double>(x.size());
        double sx = 0, sy = 0, sxx = 0, sxy = 0;
        for (size_t i = 0; i < x.size(); ++i) {
          sx += x[i], sy += y[i], sxx += x[i] * x[i], sxy += x[i] * y[i];
        }
        return (n * sxy - sx * sy) / (n * sxx - sx * sx);
      };
      CHECK(slope(y_practical) == Approx(1.0).margin(0.05));
      CHECK(slope(y_theorem) == Approx(1.0).margin(0.05));
      CHECK(slope(y_bound) == Approx(1.0).margin(0.05));
    }
  }
}

TEST_CASE("quotient equivalence: a shift along ker H leaves d_H and the bound unchanged", "[quotient][kernel]") {
  for (gen::TheoremFamily family :
       {gen::TheoremFamily::DensePsd, gen::TheoremFamily::Grid2d, gen::TheoremFamily::Grid3d}) {
    for (double eps : {0.0, 1e-3, 0.05}) {
      CAPTURE(gen::to_string(family), eps);
      const gen::TheoremTrial t = gen::theorem_problem(family, 64, eps, 41);
      REQUIRE(t.kernel.cols() > 0);
      TheoremChecker checker;
      REQUIRE(checker.precompute(t.H, t.C, t.D).ok());
      TheoremSolutions s0, s1;
      const TheoremCheck c0 = checker.check(t.A, t.b, t.q, &s0);
      REQUIRE(c0.status == TheoremStatus::Applies);
      // b' = b + Aᵀv, v ∈ ker H: X_min' = X_min + v, the same companion problem (Def. 4.2).
      const Vector<double> v = 10.0 * t.kernel * gen::gaussian_vector(t.kernel.cols(), 42);
      const Vector<double> b1 = t.b + Matrix<double>(t.A).transpose() * v;
      const TheoremCheck c1 = checker.check(t.A, b1, t.q, &s1);
      REQUIRE(c1.status == TheoremStatus::Applies);
      const double tol = 1e-9 * (1.0 + c0.exact_norm);
      CHECK((s1.X_min - s0.X_min - v).norm() <= 1e-9 * (1.0 + s0.X_min.norm() + v.norm()));
      CHECK((s1.X_star - s0.X_star - v).norm() <= 1e-9 * (1.0 + s0.X_star.norm() + v.norm()));
      CHECK((s1.demand.b_hat - s0.demand.b_hat).norm() <= tol);
      CHECK(std::abs(c1.practical_error - c0.practical_error) <= tol);
      CHECK(std::abs(c1.theorem_error - c0.theorem_error) <= tol);
      CHECK(c1.bound.bound == Approx(c0.bound.bound).epsilon(1e-8).margin(tol));
    }
  }
}

TEST_CASE("theorem_problem: deterministic, shapes as documented, ε only moves the demand", "[quotient][generators]") {
  for (gen::TheoremFamily family : gen::theorem_families()) {
    CAPTURE(gen::to_string(family));
    CHECK(gen::parse_theorem_family(gen::to_string(family)) == family);
    const gen::TheoremTrial a = gen::theorem_problem(family, 50, 0.02, 77);
    const gen::TheoremTrial b = gen::theorem_problem(family, 50, 0.02, 77);
    CHECK(Matrix<double>(a.A).isApprox(Matrix<double>(b.A)));
    CHECK(a.q == b.q);
    CHECK(a.d() >= 4);
    CHECK(a.d() <= 12);
    CHECK(a.m() <= std::min<Index>(a.d(), 6));
    CHECK(a.kernel.cols() <= a.m());
    CHECK((Matrix<double>(a.H) * a.kernel).norm() < 1e-10 * (1 + Matrix<double>(a.H).norm()));
    const Matrix<double> CAc = a.C * a.A_c;
    CHECK((Matrix<double>(a.A) - CAc - 0.02 * a.E).norm() <= 1e-12 * CAc.norm());
    CHECK(a.E.norm() == Approx(CAc.norm()));
    CHECK(a.F.norm() == Approx((a.D * a.Y).norm()));
    gen::TheoremTrial c = a;
    c.set_epsilon(0.0);
    CHECK((Matrix<double>(c.A) - CAc).norm() <= 1e-12 * CAc.norm());
    CHECK((c.q - a.D * a.Y).norm() <= 1e-12 * c.q.norm());
  }
  CHECK_THROWS_AS(gen::parse_theorem_family("nope"), std::invalid_argument);
  CHECK_THROWS_AS(gen::theorem_problem(gen::TheoremFamily::Grid2d, 10, 0.0, 1), std::invalid_argument);
  CHECK_THROWS_AS(gen::theorem_problem(gen::TheoremFamily::Grid2d, 40, -1.0, 1), std::invalid_argument);
}
