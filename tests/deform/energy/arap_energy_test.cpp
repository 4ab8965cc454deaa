// The modified ARAP energy E′ (Eq. 6–10), its Q elimination, the classic
// ARAP energy, and fit_rotation (Phase 2 of the ARAP model).
#include <catch2/catch.hpp>

#include "energy_test_util.h"

#include "qpreduce/deform/energy/arap_energy.h"
#include "qpreduce/deform/mesh/shapes.h"

#include <Eigen/Dense>
#include <Eigen/Eigenvalues>

#include <random>

using namespace qpreduce;
using namespace qpreduce::deform;

namespace {

Eigen::Matrix3d rotation(double angle, Eigen::Vector3d axis) {
  return Eigen::AngleAxisd(angle, axis.normalized()).toRotationMatrix();
}

std::vector<int> round_robin_clusters(Index r, Index d) {
  std::vector<int> c(static_cast<size_t>(r));
  for (Index k = 0; k < r; ++k) c[k] = static_cast<int>((k * d) / r);
  return c;
}

Eigen::VectorXd random_vector(Index n, unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> N;
  Eigen::VectorXd v(n);
  for (Index i = 0; i < n; ++i) v(i) = N(rng);
  return v;
}

Eigen::VectorXd rotations_vector(Index d, unsigned seed) {
  Eigen::VectorXd S(9 * d);
  for (Index i = 0; i < d; ++i) {
    const Eigen::VectorXd a = random_vector(4, seed + static_cast<unsigned>(i));
    Eigen::Map<Eigen::Matrix3d>(S.data() + 9 * i) = rotation(a(0), a.tail(3));
  }
  return S;
}

using EnergyCase = energy_test::ElementsCase;

// The small box of tets or cylinder surface in 3 round-robin clusters.
EnergyCase energy_case(bool tet) {
  EnergyCase c = energy_test::small_elements(tet, 3);
  c.clusters = round_robin_clusters(c.el.size(), c.d);
  return c;
}

// u = [V′ interleaved; Q].
Eigen::VectorXd pack(const Vertices& Vp, const Eigen::VectorXd& Q) {
  Eigen::VectorXd u(3 * Vp.rows() + Q.size());
  for (Index i = 0; i < Vp.rows(); ++i) u.segment<3>(3 * i) = Vp.row(i).transpose();
  u.tail(Q.size()) = Q;
  return u;
}

}  // namespace

TEST_CASE("E′ assembled as ½uᵀLu − SᵀDᵀu + c(S) equals the term-by-term energy", "[arap][energy]") {
  const bool tet = GENERATE(false, true);
  CAPTURE(tet);
  const EnergyCase c = energy_case(tet);
  const EnergyParameters params{0.3, tet ? 0.0 : 0.2};
  const ModifiedArapSystem sys = assemble_modified_arap(c.V, c.el, c.clusters, c.d, params);
  const Index n = c.V.rows(), r = c.el.size();
  REQUIRE(sys.L.rows() == 3 * n + 4 * r);
  REQUIRE(sys.D.cols() == 9 * c.d);

  // Symmetric and PSD.
  const Matrix<double> L(sys.L);
  CHECK((L - L.transpose()).norm() <= 1e-12 * L.norm());
  const Eigen::VectorXd ev = Eigen::SelfAdjointEigenSolver<Matrix<double>>(L).eigenvalues();
  CHECK(ev.minCoeff() >= -1e-10 * ev.maxCoeff());

  Vertices Vp = c.V;
  Vp += 0.1 * Eigen::Map<const Vertices>(random_vector(3 * n, 1).data(), n, 3);
  const Eigen::VectorXd Q = 0.05 * random_vector(4 * r, 2);
  const Eigen::VectorXd S = rotations_vector(c.d, 3);
  const Eigen::VectorXd u = pack(Vp, Q);
  // Constant term ½ Σ c ‖s e‖² = E′(0, 0, S).
  const double constant = modified_arap_energy(c.V, c.el, c.clusters, params, Vertices::Zero(n, 3),
                                               Eigen::VectorXd::Zero(4 * r), S);
  const double assembled = 0.5 * u.dot(sys.L * u) - S.dot(sys.D.transpose() * u) + constant;
  const double direct = modified_arap_energy(c.V, c.el, c.clusters, params, Vp, Q, S);
  CHECK(assembled == Approx(direct).epsilon(1e-10));

  // Gradient Lu − DS against central finite differences of the direct energy.
  const Eigen::VectorXd grad = sys.L * u - sys.D * S;
  double worst = 0.0;
  for (Index i = 0; i < u.size(); i += std::max<Index>(1, u.size() / 40)) {
    const double h = 1e-6;
    Eigen::VectorXd up = u, um = u;
    up(i) += h;
    um(i) -= h;
    auto energy_of = [&](const Eigen::VectorXd& x) {
      Vertices V2(n, 3);
      for (Index v = 0; v < n; ++v) V2.row(v) = x.segment<3>(3 * v).transpose();
      return modified_arap_energy(c.V, c.el, c.clusters, params, V2, x.tail(4 * r), S);
    };
    const double fd = (energy_of(up) - energy_of(um)) / (2 * h);
    worst = std::max(worst, std::abs(fd - grad(i)) / (1.0 + std::abs(grad(i))));
  }
  CHECK(worst < 1e-6);
}

TEST_CASE("eliminating Q gives the minimum of E′ over Q", "[arap][energy]") {
  const bool tet = GENERATE(false, true);
  CAPTURE(tet);
  const EnergyCase c = energy_case(tet);
  const EnergyParameters params{0.2, tet ? 0.0 : 0.4};
  const ModifiedArapSystem sys = assemble_modified_arap(c.V, c.el, c.clusters, c.d, params);
  const EliminatedArapSystem e = eliminate_rotation_corrections(sys);
  const Index n = c.V.rows(), r = c.el.size(), nv = 3 * n;
  const Eigen::VectorXd V = 0.3 * random_vector(nv, 4), S = rotations_vector(c.d, 5);
  // Minimise over Q directly: L_QQ Q = D_Q S − L_QV V.
  const Matrix<double> L(sys.L);
  const Matrix<double> D(sys.D);
  const Eigen::VectorXd Q = L.bottomRightCorner(4 * r, 4 * r).ldlt().solve(D.bottomRows(4 * r) * S -
                                                                             L.bottomLeftCorner(4 * r, nv) * V);
  Eigen::VectorXd u(nv + 4 * r);
  u << V, Q;
  const double full = 0.5 * u.dot(L * u) - S.dot(D.transpose() * u);
  // min_Q E′ = ½VᵀHV − SᵀD_sᵀV − ½(D_Q S)ᵀL_QQ⁻¹(D_Q S): the last term depends on S only.
  const Eigen::VectorXd DQS = D.bottomRows(4 * r) * S;
  const double s_only = -0.5 * DQS.dot(L.bottomRightCorner(4 * r, 4 * r).ldlt().solve(DQS));
  const double reduced = 0.5 * V.dot(e.H * V) - S.dot(e.Ds.transpose() * V) + s_only;
  CHECK(reduced == Approx(full).epsilon(1e-10));
  // H is exactly symmetric (assembled element by element, every (i, j) and
  // (j, i) from the same terms), PSD with the translations as null space,
  // and the dense L_VV − L_VQ·L_QQ⁻¹·L_QV to round-off.
  const Matrix<double> H(e.H);
  CHECK(H == H.transpose());
  const Matrix<double> H_dense = L.topLeftCorner(nv, nv) - L.topRightCorner(nv, 4 * r) *
                                                               L.bottomRightCorner(4 * r, 4 * r).inverse() *
                                                               L.bottomLeftCorner(4 * r, nv);
  CHECK((H - H_dense).norm() <= 1e-13 * H_dense.norm());
  const Matrix<double> Ds_dense = D.topRows(nv) - L.topRightCorner(nv, 4 * r) *
                                                      L.bottomRightCorner(4 * r, 4 * r).inverse() * D.bottomRows(4 * r);
  CHECK((Matrix<double>(e.Ds) - Ds_dense).norm() <= 1e-13 * Ds_dense.norm());
  Eigen::VectorXd tx = Eigen::VectorXd::Zero(nv);
  for (Index i = 0; i < n; ++i) tx(3 * i) = 1.0;
  CHECK((e.H * tx).norm() <= 1e-10 * H.norm());
}

TEST_CASE("the neighbour pairs of a subset of elements are the whole's pairs with both kept", "[arap][energy]") {
  const bool tet = GENERATE(false, true);
  CAPTURE(tet);
  const EnergyCase c = energy_case(tet);
  const auto whole = element_neighbours(c.el);
  REQUIRE(!whole.empty());
  std::vector<Index> keep;  // every third element, and a run in the middle
  for (Index k = 0; k < c.el.size(); ++k)
    if (k % 3 == 0 || (k > c.el.size() / 3 && k < c.el.size() / 2)) keep.push_back(k);
  const RotationElements subset = select_elements(c.el, keep);
  REQUIRE(subset.original == keep);
  std::vector<Index> position(static_cast<size_t>(c.el.size()), -1);
  for (size_t i = 0; i < keep.size(); ++i) position[static_cast<size_t>(keep[i])] = static_cast<Index>(i);
  std::vector<std::pair<Index, Index>> expected;
  for (const auto& [k, j] : whole)
    if (position[k] >= 0 && position[j] >= 0) expected.emplace_back(position[k], position[j]);
  REQUIRE(!expected.empty());
  CHECK(element_neighbours(subset) == expected);
  // A subset of the subset still knows its elements' places in the whole.
  const RotationElements twice = select_elements(subset, {1, 2});
  CHECK(twice.original == std::vector<Index>{keep[1], keep[2]});
  // With γ > 0 the subset assembles (its pairs in its own numbering); a
  // surface subset that lost its vertices is refused, not read out of range.
  EnergyParameters moving;
  moving.gamma = 0.5;
  std::vector<int> labels(keep.size());
  for (size_t i = 0; i < keep.size(); ++i) labels[i] = c.clusters[static_cast<size_t>(keep[i])];
  CHECK(assemble_modified_arap(c.V, subset, labels, c.d, moving).L.rows() ==
        3 * c.V.rows() + 4 * static_cast<Index>(keep.size()));
  if (!tet) {
    RotationElements lost = subset;
    lost.original.clear();
    CHECK_THROWS_WITH(assemble_modified_arap(c.V, lost, labels, c.d, moving), Catch::Contains("select_elements"));
  }
}

TEST_CASE("fit_rotation equals the SVD polar factor across the closed-form range", "[arap][phase2]") {
  // G = R·S, S symmetric positive definite with cond S from 1 to 99 (the
  // closed-form path takes cond G < 100): the polar factor is R exactly.
  double worst = 0.0;
  for (unsigned seed = 0; seed < 200; ++seed) {
    const Eigen::VectorXd a = random_vector(10, 1000 + seed);
    const Eigen::Matrix3d R = rotation(3.0 * a(0), a.segment<3>(1));
    const Eigen::Matrix3d Q = rotation(3.0 * a(4), a.segment<3>(5));
    const double cond = 1.0 + 98.0 * std::abs(a(8)) / (1.0 + std::abs(a(8)));
    const Eigen::Vector3d sigma(1.0, std::sqrt(cond), cond);
    const Eigen::Matrix3d S = Q * sigma.asDiagonal() * Q.transpose();
    const Eigen::Matrix3d F = fit_rotation((1.0 + std::abs(a(9))) * R * S);
    worst = std::max(worst, (F - R).norm());
    CHECK((F.transpose() * F - Eigen::Matrix3d::Identity()).norm() < 1e-13);
  }
  CHECK(worst < 1e-12);
}

TEST_CASE("fit_rotation of a flat or reflected G is the best rotation U·Vᵀ", "[arap][phase2]") {
  // G = U·diag(σ₁, σ₂, σ₃)·Vᵀ with U, V rotations, σ₂/σ₁ from 0.02 to 1 and
  // σ₃ from −0.9σ₂ (a reflection) through 0 (a flat cluster's covariance) to
  // 10⁻⁷σ₂: det G ≤ 10⁻⁶‖G‖³ or < 0, fit_rotation's SVD path. The best
  // rotation is U·Vᵀ (σ₃ < 0 is the smallest in magnitude, so flipping it
  // costs least), to round-off (the closed form would be ~10⁻¹² off at
  // σ₁/σ₂ = 50).
  double worst = 0.0;
  const double third[] = {0.0, 1e-12, 1e-9, 1e-7, -1e-9, -1e-4, -0.1, -0.5, -0.9};
  for (unsigned seed = 0; seed < 300; ++seed) {
    const Eigen::VectorXd a = random_vector(10, 9000 + seed);
    const Eigen::Matrix3d U = rotation(3.0 * a(0), a.segment<3>(1));
    const Eigen::Matrix3d V = rotation(3.0 * a(4), a.segment<3>(5));
    const double s1 = 0.5 + std::abs(a(8)), s2 = s1 * (0.02 + 0.98 * (seed % 50) / 49.0);
    const double s3 = third[seed % 9] * s2;
    const Eigen::Matrix3d G = U * Eigen::Vector3d(s1, s2, s3).asDiagonal() * V.transpose();
    const Eigen::Matrix3d F = fit_rotation(G);
    worst = std::max(worst, (F - U * V.transpose()).norm());
    CHECK((F.transpose() * F - Eigen::Matrix3d::Identity()).norm() < 1e-13);
    CHECK(F.determinant() > 0.0);
  }
  CHECK(worst < 1e-13);
}

TEST_CASE("fit_rotation's Newton path for nearly conformal input gives the exact polar factor", "[arap][phase2]") {
  // G = c·R·S with S = I + ε·(symmetric, unit norm), ε from 1e-12 to 0.08:
  // ‖XᵀX − I‖ of X = G·√3/‖G‖ is about 2ε‖E − tr E/3·I‖, below the 0.1 that
  // selects the Newton steps up to ε ≈ 0.03–0.08 (the eigenvalue path
  // beyond); either way the result must be R to round-off.
  double worst = 0.0, worst_orthogonality = 0.0;
  for (unsigned seed = 0; seed < 300; ++seed) {
    const Eigen::VectorXd a = random_vector(14, 5000 + seed);
    const Eigen::Matrix3d R = rotation(3.0 * a(0), a.segment<3>(1));
    Eigen::Matrix3d E;
    E << a(4), a(5), a(6), a(5), a(7), a(8), a(6), a(8), a(9);
    const double eps = std::pow(10.0, -12.0 + 10.9 * (seed % 100) / 99.0);  // 1e-12 … 0.08
    const Eigen::Matrix3d S = Eigen::Matrix3d::Identity() + eps * E / E.norm();
    const Eigen::Matrix3d F = fit_rotation((0.2 + std::abs(a(10))) * R * S);
    worst = std::max(worst, (F - R).norm());
    worst_orthogonality = std::max(worst_orthogonality, (F.transpose() * F - Eigen::Matrix3d::Identity()).norm());
    CHECK(F.determinant() > 0.0);
  }
  CHECK(worst < 1e-14);
  CHECK(worst_orthogonality < 1e-14);
}

TEST_CASE("fit_rotations fits every block as fit_rotation does, four at a time or alone", "[arap][phase2]") {
  // d = 1 … 11 blocks (a partial group of four at the end), mixing the
  // batched Newton path (nearly conformal, ε from 1e-12 to 0.03) with blocks
  // it must hand to fit_rotation: far from conformal, reflected, singular.
  double worst = 0.0, worst_trace = 0.0;
  for (Index d = 1; d <= 11; ++d) {
    Eigen::VectorXd s(9 * d), expected(9 * d), trace(d);
    std::vector<double> expected_trace(static_cast<size_t>(d));
    for (Index a = 0; a < d; ++a) {
      const Eigen::VectorXd r = random_vector(14, static_cast<unsigned>(700 + 16 * d + a));
      const Eigen::Matrix3d R = rotation(3.0 * r(0), r.segment<3>(1));
      Eigen::Matrix3d E;
      E << r(4), r(5), r(6), r(5), r(7), r(8), r(6), r(8), r(9);
      Eigen::Matrix3d G;
      switch ((a + d) % 5) {
        case 0: G = R * Eigen::Vector3d(3.0, 2.0, 1.0).asDiagonal(); break;       // far from conformal
        case 1: G = R * Eigen::Vector3d(1.0, 1.0, -1.0).asDiagonal(); break;      // reflected
        case 2: G = R * Eigen::Vector3d(1.0, 1.0, 1e-9).asDiagonal(); break;      // nearly singular
        default: {                                                                 // nearly conformal
          const double eps = std::pow(10.0, -12.0 + 10.5 * std::abs(r(11)) / (1.0 + std::abs(r(11))));
          G = (0.2 + std::abs(r(10))) * R * (Eigen::Matrix3d::Identity() + eps * E / E.norm());
        }
      }
      Eigen::Map<Eigen::Matrix3d>(s.data() + 9 * a) = G;
      const Eigen::Matrix3d F = fit_rotation(G);
      Eigen::Map<Eigen::Matrix3d>(expected.data() + 9 * a) = F;
      expected_trace[static_cast<size_t>(a)] = F.cwiseProduct(G).sum();
    }
    fit_rotations(s.data(), d, trace.data());
    for (Index a = 0; a < d; ++a) {
      const Eigen::Map<const Eigen::Matrix3d> F(s.data() + 9 * a), want(expected.data() + 9 * a);
      worst = std::max(worst, (F - want).norm());
      worst_trace = std::max(worst_trace, std::abs(trace(a) - expected_trace[static_cast<size_t>(a)]) /
                                              std::abs(expected_trace[static_cast<size_t>(a)]));
      CHECK(F.determinant() > 0.0);
    }
    Eigen::VectorXd again = expected;  // without trace, and on rotations: unchanged
    fit_rotations(again.data(), d);
    CHECK((again - expected).norm() < 1e-14 * std::sqrt(static_cast<double>(d)));
  }
  CHECK(worst < 1e-14);
  CHECK(worst_trace < 1e-14);
}

TEST_CASE("fit_rotations_near gives fit_rotation's rotation from any start, "
          "the same alone or in a group",
          "[arap][phase2]") {
  // Blocks of every kind fit_rotation takes (far from conformal, nearly
  // conformal, reflected with distinct singular values, rank two as a flat
  // cluster's covariance, nearly singular, tiny and huge), each from a start
  // its rounds could have: the answer turned by 0 … 0.5 rad, scaled by 2.5;
  // the identity; and starts it must hand to fit_rotation: turned by 3 rad,
  // not a rotation, zero, NaN. Every result must be fit_rotation's to
  // round-off, and a block's result the same bits alone and in a group.
  const Index d = 23;
  Eigen::VectorXd G(9 * d), start(9 * d), t(9 * d), expected(9 * d);
  for (Index a = 0; a < d; ++a) {
    const Eigen::VectorXd r = random_vector(14, static_cast<unsigned>(900 + a));
    const Eigen::Matrix3d R = rotation(3.0 * r(0), r.segment<3>(1));
    Eigen::Matrix3d E;
    E << r(4), r(5), r(6), r(5), r(7), r(8), r(6), r(8), r(9);
    Eigen::Matrix3d Ga;
    switch (a % 7) {
    case 0:
      Ga = R * Eigen::Vector3d(3.0, 2.0, 1.0).asDiagonal();
      break;
    case 1:
      Ga = R * (Eigen::Matrix3d::Identity() + 1e-3 * E / E.norm());
      break;
    case 2:
      Ga = R * Eigen::Vector3d(3.0, 2.0, -1.0).asDiagonal();
      break;
    case 3:
      Ga = R * Eigen::Vector3d(3.0, 2.0, 0.0).asDiagonal();
      break;
    case 4:
      Ga = R * Eigen::Vector3d(1.0, 1.0, 1e-9).asDiagonal();
      break;
    case 5:
      Ga = 1e-60 * R * Eigen::Vector3d(3.0, 1.0, 2.0).asDiagonal();
      break;
    default:
      Ga = 1e40 * R * Eigen::Vector3d(1.0, 2.0, 4.0).asDiagonal();
      break;
    }
    const Eigen::Matrix3d F = fit_rotation(Ga);
    Eigen::Matrix3d S;
    switch (a % 9) {
    case 0:
      S = F;
      break;
    case 1:
      S = F * rotation(1e-8, r.segment<3>(10));
      break;
    case 2:
      S = F * rotation(1e-3, r.segment<3>(10));
      break;
    case 3:
      S = F * rotation(0.1, r.segment<3>(10));
      break;
    case 4:
      S = 2.5 * F * rotation(0.5, r.segment<3>(10));
      break;
    case 5:
      S = Eigen::Matrix3d::Identity();
      break;
    case 6:
      S = F * rotation(3.0, r.segment<3>(10));
      break;
    case 7:
      S = F + 0.01 * E;
      break;
    default:
      S = a % 2 == 0 ? Eigen::Matrix3d::Zero()
                     : Eigen::Matrix3d::Constant(std::nan(""));
      break;
    }
    Eigen::Map<Eigen::Matrix3d>(G.data() + 9 * a) = Ga;
    Eigen::Map<Eigen::Matrix3d>(start.data() + 9 * a) = S;
    Eigen::Map<Eigen::Matrix3d>(expected.data() + 9 * a) = F;
  }
  // Blocks that must go to fit_rotation: starts 7 and 8, the tiny G (5);
  // a start 3 rad away and the identity (the answer is a random rotation)
  // may or may not.
  Index must = 0, may = 0;
  for (Index a = 0; a < d; ++a) {
    if (a % 9 == 7 || a % 9 == 8 || a % 7 == 5)
      ++must;
    else if (a % 9 == 6 || a % 9 == 5)
      ++may;
  }
  const Index fallbacks =
      fit_rotations_near(G.data(), start.data(), t.data(), d);
  CHECK(fallbacks >= must);
  CHECK(fallbacks <= must + may);
  double worst = 0.0;
  for (Index a = 0; a < d; ++a) {
    const Eigen::Map<const Eigen::Matrix3d> T(t.data() + 9 * a),
        F(expected.data() + 9 * a);
    INFO("block " << a);
    CHECK((T - F).norm() < 1e-13);
    CHECK((T.transpose() * T - Eigen::Matrix3d::Identity()).norm() < 1e-14);
    worst = std::max(worst, (T - F).norm());
    Eigen::Matrix3d alone;
    const Index one_fallback = fit_rotations_near(
        G.data() + 9 * a, start.data() + 9 * a, alone.data(), 1);
    UNSCOPED_INFO("block " << a << " G kind " << a % 7 << " start kind "
                           << a % 9 << " fallback " << one_fallback);
    CHECK((alone - T).cwiseAbs().maxCoeff() == 0.0);
  }
  CHECK(worst < 1e-13);
}

TEST_CASE("fit_rotation returns a proper rotation even for reflected input", "[arap][phase2]") {
  for (unsigned seed = 0; seed < 50; ++seed) {
    const Eigen::VectorXd a = random_vector(4, seed);
    const Eigen::Matrix3d R = rotation(a(0), a.tail(3));
    Eigen::Matrix3d G = R * Eigen::Vector3d(3.0, 2.0, 1.0).asDiagonal();
    if (seed % 2) G.col(seed % 3) *= -1.0;  // reflected
    const Eigen::Matrix3d F = fit_rotation(G);
    CHECK(F.determinant() == Approx(1.0).epsilon(1e-12));
    CHECK((F.transpose() * F - Eigen::Matrix3d::Identity()).norm() < 1e-12);
    if (seed % 2 == 0) CHECK((F - R).norm() < 1e-12);  // unreflected: recovers R
    // The fit maximises tr(FᵀG) over SO(3): no nearby rotation does better.
    for (int k = 0; k < 3; ++k) {
      Eigen::Vector3d axis = Eigen::Vector3d::Zero();
      axis(k) = 1.0;
      for (double eps : {1e-4, -1e-4}) CHECK((rotation(eps, axis) * F).cwiseProduct(G).sum() <= F.cwiseProduct(G).sum() + 1e-12);
    }
  }
}

TEST_CASE("fit_rotation_planar equals the SVD fit for covariances of planar elements", "[arap][phase2]") {
  // G = Σ c e′eᵀ with every rest edge e ⟂ n (rank 2, G n = 0), e′ = R·S·e
  // plus noise, some with negative weights (cot) or reflected: the SVD
  // maximiser U·diag(1, 1, det UVᵀ)·Vᵀ is unique there and must be matched
  // to round-off; nearly collinear edges take the fallback.
  double worst = 0.0;
  int compared = 0;
  for (unsigned seed = 0; seed < 300; ++seed) {
    const Eigen::VectorXd a = random_vector(40, 9000 + seed);
    const Eigen::Vector3d n = a.segment<3>(0).normalized();
    const Eigen::Matrix3d R = rotation(3.0 * a(3), a.segment<3>(4));
    Eigen::Matrix3d G = Eigen::Matrix3d::Zero();
    for (int k = 0; k < 6; ++k) {
      Eigen::Vector3d e = a.segment<3>(8 + 3 * k);
      e -= n.dot(e) * n;
      if (seed % 7 == 0) e = (1.0 + 1e-5 * k) * (a.segment<3>(8) - n.dot(a.segment<3>(8)) * n);  // collinear
      const Eigen::Vector3d ep = R * (e + 0.3 * a.segment<3>(26 + (k % 4) * 3).cwiseProduct(e));
      G += (k == 5 && seed % 3 == 0 ? -0.2 : 1.0) * ep * e.transpose();
    }
    if (seed % 5 == 1) G.row(0) *= -1.0;  // reflected (still G n = 0)
    const Eigen::JacobiSVD<Eigen::Matrix3d> svd(G, Eigen::ComputeFullU | Eigen::ComputeFullV);
    Eigen::Matrix3d U = svd.matrixU();
    if ((U * svd.matrixV().transpose()).determinant() < 0) U.col(2) *= -1.0;
    const Eigen::Matrix3d expected = U * svd.matrixV().transpose();
    const Eigen::Matrix3d F = fit_rotation_planar(G, n);
    CHECK(F.determinant() == Approx(1.0).epsilon(1e-12));
    CHECK((F.transpose() * F - Eigen::Matrix3d::Identity()).norm() < 1e-12);
    if (svd.singularValues()(1) > 1e-8 * svd.singularValues()(0)) {  // unique maximiser
      // Both fits are exact to round-off times σ₁/σ₂ (the sensitivity of
      // the maximiser), which is what is compared.
      worst = std::max(worst, (F - expected).norm() * svd.singularValues()(1) / svd.singularValues()(0));
      ++compared;
    }
    CHECK(F.cwiseProduct(G).sum() >= expected.cwiseProduct(G).sum() - 1e-12 * G.norm());
  }
  CHECK(compared > 200);
  CHECK(worst < 1e-14);
}

TEST_CASE("classic ARAP energy is zero at rest and invariant under rigid motion", "[arap][energy]") {
  const bool tet = GENERATE(false, true);
  const EnergyCase c = energy_case(tet);
  CHECK(arap_energy(c.V, c.el, c.V) == Approx(0.0).margin(1e-20));
  const Eigen::Matrix3d R = rotation(0.7, Eigen::Vector3d(1, 2, 3));
  Vertices moved = (c.V * R.transpose()).rowwise() + Eigen::RowVector3d(1, -2, 0.5);
  CHECK(arap_energy(c.V, c.el, moved) == Approx(0.0).margin(1e-18));
  Vertices bent = c.V;
  bent.col(0) += 0.1 * bent.col(2).array().square().matrix();
  CHECK(arap_energy(c.V, c.el, bent) > 1e-6);
}
