// Test models for the alternation (alternation_test.cpp, the white-box
// alternation_parts_test.cpp).
#pragma once

#include <catch2/catch.hpp>

#include "qpreduce/alternation.h"
#include "qpreduce/problems/generators.h"
#include "qpreduce/subspace_solver.h"

#include <Eigen/Dense>

#include <algorithm>
#include <vector>

namespace qpreduce::testing_alternation {

namespace gen = qpreduce::generators;

// Constraints on y: a model with the deformer's structure, E(z, y) =
// ½XᵀHX − XᵀD·y + ½‖y‖², X = N z + UD·y, whose Phase 2 input is the exact
// y-coefficient g = DᵀX (G_z = DᵀN, G_y = DᵀUD), with y on a product of
// unit spheres (blocks of 3: ‖y‖ is constant there, so Π(g) normalises
// each block of g). Point constraints AᵀX = b at vertices that are not
// proxies involve y (A_y = AᵀUD ≠ 0).
struct UnitBlocks : InputProjection<double> {
  static constexpr Index kBlock = 3;
  double project(const Eigen::Ref<const Vector<double>>& g, Eigen::Ref<Vector<double>> y) override {
    const Vector<double> old = y;
    for (Index j = 0; j < g.size() / kBlock; ++j) y.segment(kBlock * j, kBlock) = g.segment(kBlock * j, kBlock).normalized();
    return (y - old).norm();
  }
  double quadratic_term(const Eigen::Ref<const Vector<double>>& y) const override { return 0.5 * y.squaredNorm(); }
  void retract(Eigen::Ref<Vector<double>> y) const override {
    for (Index j = 0; j < y.size() / kBlock; ++j) y.segment(kBlock * j, kBlock).normalize();
  }
  Index proximal_block_size() const override { return kBlock; }
};

struct SphereModel {
  Index nx = 14, ny = 11, n = nx * ny, d = 9, k = 12, m = 6;
  SparseMatrix<double> H = gen::grid_laplacian_2d(nx, ny);
  std::vector<Index> proxies = gen::random_subset(n, d, 5);
  SparseMatrix<double> C = gen::selection(n, proxies);
  SparseMatrix<double> D = gen::gaussian_sparse(n, k, 6);
  SubspaceSolver<double> solver;
  SparseMatrix<double> A;
  Vector<double> b;
  Matrix<double> Gz, Gy;
  SphereModel() {
    REQUIRE(solver.precompute(H, C, D).ok());
    std::vector<Index> rows;  // constrained vertices away from the proxies
    for (Index v : gen::random_subset(n, 3 * m, 41))
      if (std::find(proxies.begin(), proxies.end(), v) == proxies.end() && static_cast<Index>(rows.size()) < m)
        rows.push_back(v);
    REQUIRE(static_cast<Index>(rows.size()) == m);
    A = gen::selection(n, rows);
    b = 3.0 * gen::gaussian_vector(m, 42);
    const Matrix<double> Dd(D);
    Gz = Dd.transpose() * solver.subspace().N;
    Gy = Dd.transpose() * solver.subspace().UD;
  }
  // E(y) with z the Phase 1 minimiser, by a dense KKT solve (independent of
  // the engine's energy terms).
  double energy(const Vector<double>& y) const {
    const Matrix<double>& N = solver.subspace().N;
    const Matrix<double>& U = solver.subspace().UD;
    const Matrix<double> Hd(H), Ad(A), Dd(D);
    Matrix<double> K = Matrix<double>::Zero(d + m, d + m);
    K.topLeftCorner(d, d) = N.transpose() * Hd * N;
    K.topRightCorner(d, m) = N.transpose() * Ad;
    K.bottomLeftCorner(m, d) = Ad.transpose() * N;
    Vector<double> rhs(d + m);
    rhs.head(d) = N.transpose() * (Dd * y) - N.transpose() * Hd * U * y;
    rhs.tail(m) = b - Ad.transpose() * U * y;
    const Vector<double> z = K.fullPivLu().solve(rhs).head(d);
    const Vector<double> X = N * z + U * y;
    return 0.5 * X.dot(Hd * X) - X.dot(Dd * y) + 0.5 * y.squaredNorm();
  }
  Vector<double> start() const {
    Vector<double> y = gen::gaussian_vector(k, 43);
    UnitBlocks().retract(y);
    return y;
  }
};

}  // namespace qpreduce::testing_alternation
