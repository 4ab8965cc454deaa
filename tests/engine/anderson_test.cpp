// AndersonAcceleration (anderson.h) on linear contractions x ← Mx + c, whose
// fixed point x* = (I − M)⁻¹c is known.
#include <qpreduce/anderson.h>

#include <catch2/catch.hpp>

#include <Eigen/Dense>

#include <cmath>
#include <limits>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

using qpreduce::AndersonAcceleration;
using qpreduce::AndersonOptions;

namespace {

// A symmetric contraction with spectral radius `radius` (eigenvalues spread
// over [0, radius]) and a seeded offset.
struct Contraction {
  Eigen::MatrixXd M;
  Eigen::VectorXd c, fixed_point;
};

Contraction make_contraction(int n, double radius, unsigned seed) {
  std::mt19937 gen(seed);
  std::normal_distribution<double> normal;
  Eigen::MatrixXd A(n, n);
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) A(i, j) = normal(gen);
  const Eigen::MatrixXd Qm = Eigen::HouseholderQR<Eigen::MatrixXd>(A).householderQ();
  const Eigen::VectorXd eig = Eigen::VectorXd::LinSpaced(n, 0.0, radius);
  Contraction k;
  k.M = Qm * eig.asDiagonal() * Qm.transpose();
  k.c = Eigen::VectorXd::NullaryExpr(n, [&] { return normal(gen); });
  k.fixed_point = (Eigen::MatrixXd::Identity(n, n) - k.M).lu().solve(k.c);
  return k;
}

// Steps until ‖x − x*‖ ≤ tol‖x*‖ (at most max_steps); window 0 = plain iteration.
int steps_to_converge(const Contraction& k, int window, double tol, int max_steps) {
  const Eigen::Index n = k.c.size();
  Eigen::VectorXd x = Eigen::VectorXd::Zero(n), g(n);
  AndersonAcceleration aa;
  if (window > 0) aa.reset(n, AndersonOptions{window});
  for (int s = 0; s < max_steps; ++s) {
    if ((x - k.fixed_point).norm() <= tol * k.fixed_point.norm()) return s;
    g = k.M * x + k.c;
    if (window > 0) aa.step(x, g, g);  // out aliases gx
    x = g;
  }
  return max_steps;
}

}  // namespace

TEST_CASE("Anderson reaches the fixed point of a linear contraction in far fewer steps than the plain iteration") {
  const Contraction k = make_contraction(60, 0.99, 7);
  const int plain = steps_to_converge(k, 0, 1e-10, 100000);
  REQUIRE(plain > 1500);  // ρ = 0.99: about log(1e-10)/log(0.99) steps
  const int window = GENERATE(1, 2, 5, 8, 16);
  const int accelerated = steps_to_converge(k, window, 1e-10, 100000);
  INFO("window " << window << ": " << accelerated << " steps, plain " << plain);
  CHECK(accelerated * 2 < plain);              // every window helps
  if (window >= 5) CHECK(accelerated * 5 < plain);  // the default and larger: far fewer
}

TEST_CASE("Anderson: the first step after reset and after restart is the plain step") {
  const Contraction k = make_contraction(10, 0.5, 3);
  AndersonAcceleration aa;
  aa.reset(10, AndersonOptions{3});
  CHECK(aa.size() == 10);
  Eigen::VectorXd x = Eigen::VectorXd::Ones(10), out(10);
  Eigen::VectorXd g = k.M * x + k.c;
  aa.step(x, g, out);
  CHECK(out == g);
  CHECK(aa.history() == 0);
  for (int s = 0; s < 5; ++s) {
    x = out;
    g = k.M * x + k.c;
    aa.step(x, g, out);
    CHECK(aa.history() == std::min(s + 1, 3));
    CHECK(out.allFinite());
  }
  CHECK(out != g);  // accelerated
  aa.restart();
  CHECK(aa.history() == 0);
  CHECK(aa.size() == 10);
  x = out;
  g = k.M * x + k.c;
  aa.step(x, g, out);
  CHECK(out == g);
}

TEST_CASE("Anderson: every step is G(x_k) − ΔG·θ with θ the least-squares fit of f_k by ΔF") {
  // Arbitrary (x, G(x)) pairs, so that nothing but the definition (anderson.h)
  // predicts the output: the window fills and wraps, a restart drops the
  // history, and each step is checked against θ from a QR of the last
  // differences (the class updates ΔFᵀΔF and ΔFᵀf incrementally).
  const Eigen::Index n = 37;
  for (int window : {1, 3, 5}) {
    CAPTURE(window);
    std::mt19937 gen(static_cast<unsigned>(90 + window));
    std::normal_distribution<double> normal;
    AndersonAcceleration aa;
    aa.reset(n, AndersonOptions{window});
    std::vector<Eigen::VectorXd> fs, gs;  // f and G(x) since the last restart
    double worst = 0.0;
    for (int s = 0; s < 20; ++s) {
      if (s == 11) {
        aa.restart();
        fs.clear();
        gs.clear();
      }
      const Eigen::VectorXd x = Eigen::VectorXd::NullaryExpr(n, [&] { return normal(gen); });
      const Eigen::VectorXd gx = x + Eigen::VectorXd::NullaryExpr(n, [&] { return normal(gen); }) / (1.0 + s);
      fs.push_back(gx - x);
      gs.push_back(gx);
      Eigen::VectorXd out(n);
      aa.step(x, gx, out);
      const int h = std::min<int>(window, static_cast<int>(fs.size()) - 1);
      REQUIRE(aa.history() == h);
      Eigen::VectorXd expected = gx;
      if (h > 0) {
        Eigen::MatrixXd dF(n, h), dG(n, h);
        for (int j = 0; j < h; ++j) {
          const size_t newer = fs.size() - static_cast<size_t>(h) + static_cast<size_t>(j);
          dF.col(j) = fs[newer] - fs[newer - 1];
          dG.col(j) = gs[newer] - gs[newer - 1];
        }
        const Eigen::VectorXd theta = dF.colPivHouseholderQr().solve(fs.back());
        expected -= dG * theta;
      }
      worst = std::max(worst, (out - expected).norm() / expected.norm());
    }
    CHECK(worst < 1e-10);
  }
}

TEST_CASE("Anderson with a repeated iterate (zero differences) stays finite") {
  AndersonAcceleration aa;
  aa.reset(4, AndersonOptions{4});
  const Eigen::VectorXd x = Eigen::VectorXd::Constant(4, 2.0), g = Eigen::VectorXd::Constant(4, 2.0);
  Eigen::VectorXd out(4);
  for (int s = 0; s < 6; ++s) {
    aa.step(x, g, out);
    REQUIRE(out.allFinite());
    CHECK((out - g).norm() == Approx(0.0).margin(1e-12));
  }
}

TEST_CASE("Anderson: bad options and sizes throw with the words") {
  AndersonAcceleration aa;
  std::string why;
  CHECK_FALSE(AndersonOptions{0}.is_valid(&why));
  CHECK(why == "window must be in [1, 16], got 0");
  CHECK_FALSE(AndersonOptions{17}.is_valid(&why));
  CHECK(why == "window must be in [1, 16], got 17");
  CHECK(AndersonOptions{16}.is_valid(&why));
  CHECK_THROWS_WITH(aa.reset(5, AndersonOptions{0}), Catch::Contains("window must be in [1, 16], got 0"));
  CHECK_THROWS_WITH(aa.reset(5, AndersonOptions{17}), Catch::Contains("got 17"));
  CHECK_THROWS_WITH(aa.reset(0, AndersonOptions{}), Catch::Contains("at least 1, got 0"));
  const Eigen::VectorXd v5 = Eigen::VectorXd::Zero(5), v4 = Eigen::VectorXd::Zero(4);
  Eigen::VectorXd out5(5), out4(4);
  CHECK_THROWS_WITH(aa.step(v5, v5, out5), Catch::Contains("call reset first"));
  aa.reset(5, AndersonOptions{});
  CHECK_THROWS_WITH(aa.step(v4, v5, out5), Catch::Contains("expected 5, got 4"));
  CHECK_THROWS_WITH(aa.step(v5, v4, out5), Catch::Contains("gx"));
  CHECK_THROWS_WITH(aa.step(v5, v5, out4), Catch::Contains("out"));
}

TEST_CASE("SafeguardedAnderson: a quadratic's energy judges the steps, and refusals restart the history and are counted") {
  // x ← Mx + c is the gradient step of E(x) = ½xᵀ(I − M)x − cᵀx (I − M ≻ 0),
  // so the safeguarded loop never raises E and reaches x* as the plain one.
  using qpreduce::SafeguardedAnderson;
  const Contraction k = make_contraction(40, 0.98, 11);
  const Eigen::Index n = k.c.size();
  const Eigen::MatrixXd K = Eigen::MatrixXd::Identity(n, n) - k.M;
  const auto energy = [&](const Eigen::VectorXd& x) { return 0.5 * x.dot(K * x) - k.c.dot(x); };
  SafeguardedAnderson aa;
  aa.reset(n, AndersonOptions{5});
  Eigen::VectorXd x = Eigen::VectorXd::Zero(n), gx(n), trial(n);
  double accepted = energy(x);
  int steps = 0;
  for (; steps < 2000 && (x - k.fixed_point).norm() > 1e-10 * k.fixed_point.norm(); ++steps) {
    gx = k.M * x + k.c;
    if (aa.propose(x, gx, trial)) {
      const double e = energy(trial);
      if (aa.accept(e, accepted)) {
        CHECK(e <= accepted);
        x = trial;
        accepted = e;
        continue;
      }
    }
    x = gx;  // the plain step: never raises E
    const double e = energy(x);
    CHECK(e <= accepted + 1e-12 * std::abs(accepted));
    accepted = e;
  }
  CHECK(steps < 400);  // plain: about log(1e-10)/log(0.98) ≈ 1,100

  // The judgement itself: higher or non-finite energies are refused, each
  // refusal counted and the history dropped (the next proposal is G(x)).
  const int before = aa.rejected();
  CHECK(aa.accept(1.0, 1.0));
  CHECK(aa.accept(1.0 + 1e-13, 1.0, 1e-12));  // within the slack
  CHECK_FALSE(aa.accept(2.0, 1.0));
  CHECK(aa.history() == 0);
  CHECK_FALSE(aa.accept(std::numeric_limits<double>::quiet_NaN(), 1.0));
  CHECK(aa.rejected() == before + 2);
  gx = k.M * x + k.c;
  CHECK_FALSE(aa.propose(x, gx, trial));
  CHECK(trial == gx);
  aa.restart();
  CHECK(aa.rejected() == 0);
  CHECK_THROWS_AS(aa.reset(n, AndersonOptions{0}), std::invalid_argument);
}
