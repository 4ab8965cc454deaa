// White-box tests of the precompute's threaded sparse products
// (plugins/deform/src/energy/sparse_products.h).
#include <catch2/catch.hpp>

#include "energy/sparse_products.h"

#include <omp.h>

#include <array>
#include <random>
#include <vector>

using namespace qpreduce;
using qpreduce::deform::detail::is_identity;
using qpreduce::deform::detail::parallel_product;

namespace {

SparseMatrix<double> random_sparse(Index rows, Index cols, Index per_column, unsigned seed) {
  std::mt19937 gen(seed);
  std::uniform_int_distribution<Index> row(0, rows - 1);
  std::normal_distribution<double> value;
  std::vector<Eigen::Triplet<double>> t;
  for (Index j = 0; j < cols; ++j)
    for (Index k = 0; k < per_column; ++k) t.emplace_back(row(gen), j, value(gen));
  SparseMatrix<double> m(rows, cols);
  m.setFromTriplets(t.begin(), t.end());
  return m;
}

// Same pattern and bitwise the same values.
bool identical(const SparseMatrix<double>& a, const SparseMatrix<double>& b) {
  if (a.rows() != b.rows() || a.cols() != b.cols() || a.nonZeros() != b.nonZeros()) return false;
  for (Index j = 0; j < a.outerSize(); ++j) {
    SparseMatrix<double>::InnerIterator ia(a, j), ib(b, j);
    for (; ia && ib; ++ia, ++ib)
      if (ia.row() != ib.row() || ia.value() != ib.value()) return false;
    if (ia || ib) return false;
  }
  return true;
}

}  // namespace

TEST_CASE("parallel_product equals Eigen's sequential product bitwise", "[deform][sparse]") {
  const int threads = GENERATE(1, 2, 3);
  CAPTURE(threads);
  const int previous = omp_get_max_threads();
  omp_set_num_threads(threads);
  // Tall, wide and square shapes (Eigen picks a different kernel for each).
  for (const auto& [rows, inner, cols] : std::vector<std::array<Index, 3>>{{900, 400, 300}, {300, 500, 900}, {700, 700, 700}}) {
    CAPTURE(rows, inner, cols);
    const SparseMatrix<double> A = random_sparse(rows, inner, 6, 1), B = random_sparse(inner, cols, 5, 2);
    const SparseMatrix<double> expected = A * B;
    CHECK(identical(parallel_product(A, B), expected));
    const SparseMatrix<double> At = A.transpose();
    CHECK(identical(parallel_product(At, A), SparseMatrix<double>(At * A)));
  }
  // Fewer columns than 4 per thread and empty operands take the sequential path.
  const SparseMatrix<double> A = random_sparse(50, 40, 3, 3), B = random_sparse(40, 5, 3, 4);
  CHECK(identical(parallel_product(A, B), SparseMatrix<double>(A * B)));
  const SparseMatrix<double> Z(40, 0);
  CHECK(parallel_product(A, Z).cols() == 0);
  omp_set_num_threads(previous);
}

TEST_CASE("is_identity recognises only the identity", "[deform][sparse]") {
  SparseMatrix<double> I(6, 6);
  I.setIdentity();
  CHECK(is_identity(I));
  SparseMatrix<double> scaled = 2.0 * I;
  CHECK_FALSE(is_identity(scaled));
  SparseMatrix<double> off = I;
  off.coeffRef(0, 1) = 1.0;
  CHECK_FALSE(is_identity(off));
  SparseMatrix<double> permuted(2, 2);
  permuted.insert(1, 0) = 1.0;
  permuted.insert(0, 1) = 1.0;
  CHECK_FALSE(is_identity(permuted));
  CHECK_FALSE(is_identity(SparseMatrix<double>(6, 7)));
}
