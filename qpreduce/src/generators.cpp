#include "qpreduce/generators.h"

#include <Eigen/QR>
#include <fmt/format.h>

#include <algorithm>
#include <numeric>
#include <random>

namespace qpreduce::generators {

namespace {
using Triplets = std::vector<Eigen::Triplet<double>>;

void add_edge(Triplets& t, Index a, Index b) {
  t.emplace_back(a, a, 1.0);
  t.emplace_back(b, b, 1.0);
  t.emplace_back(a, b, -1.0);
  t.emplace_back(b, a, -1.0);
}

void add_ridge(Triplets& t, Index n, double ridge) {
  if (ridge == 0.0) return;
  for (Index i = 0; i < n; ++i) t.emplace_back(i, i, ridge);
}

void require_positive(const char* what, Index v) {
  if (v <= 0) throw std::invalid_argument(fmt::format("{}: expected a positive size, got {}", what, v));
}
}  // namespace

SparseMatrix<double> grid_laplacian_2d(Index nx, Index ny, double ridge) {
  require_positive("grid_laplacian_2d: nx", nx);
  require_positive("grid_laplacian_2d: ny", ny);
  const Index n = nx * ny;
  Triplets t;
  t.reserve(static_cast<size_t>(8 * n + n));
  for (Index j = 0; j < ny; ++j)
    for (Index i = 0; i < nx; ++i) {
      const Index v = i + nx * j;
      if (i + 1 < nx) add_edge(t, v, v + 1);
      if (j + 1 < ny) add_edge(t, v, v + nx);
    }
  add_ridge(t, n, ridge);
  SparseMatrix<double> L(n, n);
  L.setFromTriplets(t.begin(), t.end());
  return L;
}

SparseMatrix<double> grid_laplacian_3d(Index nx, Index ny, Index nz, double ridge) {
  require_positive("grid_laplacian_3d: nx", nx);
  require_positive("grid_laplacian_3d: ny", ny);
  require_positive("grid_laplacian_3d: nz", nz);
  const Index n = nx * ny * nz;
  Triplets t;
  t.reserve(static_cast<size_t>(12 * n + n));
  for (Index k = 0; k < nz; ++k)
    for (Index j = 0; j < ny; ++j)
      for (Index i = 0; i < nx; ++i) {
        const Index v = i + nx * (j + ny * k);
        if (i + 1 < nx) add_edge(t, v, v + 1);
        if (j + 1 < ny) add_edge(t, v, v + nx);
        if (k + 1 < nz) add_edge(t, v, v + nx * ny);
      }
  add_ridge(t, n, ridge);
  SparseMatrix<double> L(n, n);
  L.setFromTriplets(t.begin(), t.end());
  return L;
}

Matrix<double> gaussian_matrix(Index rows, Index cols, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> normal;
  Matrix<double> M(rows, cols);
  for (Index j = 0; j < cols; ++j)
    for (Index i = 0; i < rows; ++i) M(i, j) = normal(rng);
  return M;
}

Vector<double> gaussian_vector(Index n, std::uint64_t seed) { return gaussian_matrix(n, 1, seed).col(0); }

SparseMatrix<double> random_psd(Index n, Index nullity, std::uint64_t seed, Matrix<double>* null_basis) {
  require_positive("random_psd: n", n);
  if (nullity < 0 || nullity >= n) {
    throw std::invalid_argument(fmt::format("random_psd: nullity must lie in [0, {}), got {}", n, nullity));
  }
  const Matrix<double> G = gaussian_matrix(n - nullity, n, seed);
  Matrix<double> H = G.transpose() * G;
  H = 0.5 * (H + H.transpose()).eval();
  if (null_basis) {
    // ker(H) = ker(G): the last `nullity` columns of the full Q of Gᵀ.
    Eigen::HouseholderQR<Matrix<double>> qr(G.transpose());
    const Matrix<double> Q = qr.householderQ();
    *null_basis = Q.rightCols(nullity);
  }
  return H.sparseView();
}

SparseMatrix<double> selection(Index n, const std::vector<Index>& rows) {
  SparseMatrix<double> S(n, static_cast<Index>(rows.size()));
  Triplets t;
  for (size_t j = 0; j < rows.size(); ++j) {
    if (rows[j] < 0 || rows[j] >= n) {
      throw std::invalid_argument(fmt::format("selection: row {} out of range [0, {})", rows[j], n));
    }
    t.emplace_back(rows[j], static_cast<Index>(j), 1.0);
  }
  S.setFromTriplets(t.begin(), t.end());
  return S;
}

std::vector<Index> random_subset(Index n, Index count, std::uint64_t seed) {
  if (count < 0 || count > n) {
    throw std::invalid_argument(fmt::format("random_subset: count must lie in [0, {}], got {}", n, count));
  }
  std::vector<Index> all(static_cast<size_t>(n));
  std::iota(all.begin(), all.end(), Index(0));
  std::mt19937_64 rng(seed);
  // Partial Fisher–Yates.
  for (Index i = 0; i < count; ++i) {
    std::uniform_int_distribution<Index> pick(i, n - 1);
    std::swap(all[static_cast<size_t>(i)], all[static_cast<size_t>(pick(rng))]);
  }
  std::vector<Index> out(all.begin(), all.begin() + count);
  std::sort(out.begin(), out.end());
  return out;
}

SparseMatrix<double> gaussian_sparse(Index n, Index cols, std::uint64_t seed) {
  return gaussian_matrix(n, cols, seed).sparseView();
}

SparseMatrix<double> grid_trend_basis(Index nx, Index ny, Index k) {
  require_positive("grid_trend_basis: nx", nx);
  require_positive("grid_trend_basis: ny", ny);
  if (k < 0 || k > 10) throw std::invalid_argument(fmt::format("grid_trend_basis: k must lie in [0, 10], got {}", k));
  // Monomials x^a y^b in graded order, on coordinates scaled to [−1, 1].
  static const int powers[10][2] = {{0, 0}, {1, 0}, {0, 1}, {1, 1}, {2, 0}, {0, 2}, {2, 1}, {1, 2}, {3, 0}, {0, 3}};
  const Index n = nx * ny;
  Matrix<double> T(n, k);
  for (Index j = 0; j < ny; ++j)
    for (Index i = 0; i < nx; ++i) {
      const double x = nx > 1 ? 2.0 * i / (nx - 1) - 1.0 : 0.0;
      const double y = ny > 1 ? 2.0 * j / (ny - 1) - 1.0 : 0.0;
      for (Index c = 0; c < k; ++c) T(i + nx * j, c) = std::pow(x, powers[c][0]) * std::pow(y, powers[c][1]);
    }
  return T.sparseView();
}

}  // namespace qpreduce::generators
