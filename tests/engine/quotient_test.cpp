// Quotient equivalence (Section 4): the factor H = LᵀL, the whitened design,
// the closed forms of Prop. 4.6/4.7/4.9 against KKT solves, and bad input.
// The error bound of Theorem 4.10 is tested in theorem_test.cpp.
#include <catch2/catch.hpp>

#include "qpreduce/problems/generators.h"
#include "qpreduce/quotient.h"
#include "qpreduce/theorem.h"

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

std::string message_of(const std::function<void()>& f) {
  try {
    f();
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
  return "no exception";
}

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
  SECTION("empty H (n = 0)") {
    CHECK_THAT(message_of([&] { factor_psd(SparseMatrix<double>(0, 0), {}, &f); }), Catch::Contains("H is empty"));
    CHECK_THAT(message_of([&] { factor_psd(Matrix<double>(0, 0), {}, &f); }), Catch::Contains("H is empty"));
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
