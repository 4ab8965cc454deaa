// Theorem 4.10 (Eq. 39): the bound's terms and failed hypotheses, the
// TheoremChecker on seeded trials (generators::theorem_problem) across
// families and ε, what the bound covers when ker H leaves the design, the
// linear rate in ε, and quotient equivalence along ker H.
#include <catch2/catch.hpp>

#include "qpreduce/problems/generators.h"
#include "qpreduce/theorem.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <vector>

using namespace qpreduce;
namespace gen = qpreduce::generators;

namespace {

constexpr double kMachineEpsilon = std::numeric_limits<double>::epsilon();

std::string fmt_trial(gen::TheoremFamily family, Index size, double eps, std::uint64_t seed) {
  return fmt::format("theorem_problem({}, {}, {}, {})", gen::to_string(family), size, eps, seed);
}

// Sizes used by the trial sweep: small enough for the ASan build.
Index sweep_size(int group) { return 30 + (group * 13) % 70; }

const std::vector<double> kSweepEpsilons = {0.0, 1e-7, 1e-6, 1e-5, 1e-4, 1e-3, 1e-2, 3e-2, 0.1, 0.3};

}  // namespace

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
      CHECK(c.bound.q_residual <= 100 * r * kMachineEpsilon * whiten_norm * t.q.norm());
      CHECK(c.bound.A_residual <= 100 * r * kMachineEpsilon * whiten_norm * Matrix<double>(t.A).norm());
      CHECK(c.bound.rho <= 100 * r * kMachineEpsilon * c.bound.omega);
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
