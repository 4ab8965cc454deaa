// k-means: determinism for a seed, exactly k non-empty clusters, errors.
#include <catch2/catch.hpp>

#include "proxies_test_util.h"

#include <random>
#include <stdexcept>

using namespace qpreduce;
using namespace qpreduce::deform;
using namespace proxies_test;

TEST_CASE("k-means is deterministic for a seed and returns exactly k non-empty clusters", "[kmeans]") {
  std::mt19937_64 rng(3);
  Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> X(300, 4);
  for (Index i = 0; i < X.rows(); ++i) {
    for (Index j = 0; j < X.cols(); ++j) X(i, j) = static_cast<double>(rng() >> 11) * 0x1.0p-53 + (i % 5);
  }
  const Index k = GENERATE(1, 5, 17, 300);
  CAPTURE(k);
  KMeansOptions o;
  o.seed = 42;
  const KMeansResult a = kmeans(X, k, o), b = kmeans(X, k, o);
  CHECK(a.labels == b.labels);
  check_partition(a.labels, k);
  CHECK(a.converged);
  CHECK(a.centres.rows() == k);
  if (k == 300) CHECK(a.objective == 0.0);
  // The objective is the sum of squared distances to the reported centres.
  double objective = 0.0;
  for (Index i = 0; i < X.rows(); ++i) objective += (X.row(i) - a.centres.row(a.labels[i])).squaredNorm();
  CHECK(std::abs(objective - a.objective) <= 1e-12 * (1.0 + objective));
  if (k == 5) {
    // Five well-separated blobs (offsets 0..4 in every coordinate): recovered.
    for (Index i = 0; i < X.rows(); ++i) CHECK(a.labels[i] == a.labels[i % 5]);
  }
  if (k == 17) {
    // Different seeds give valid (possibly different) partitions.
    o.seed = 43;
    check_partition(kmeans(X, k, o).labels, k);
  }
}

TEST_CASE("k-means with coincident points still gives k non-empty clusters, bad k throws", "[kmeans][errors]") {
  const Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> X =
      Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>::Ones(10, 2);
  check_partition(kmeans(X, 4).labels, 4);
  CHECK_THROWS_WITH(kmeans(X, 11), Catch::Contains("[1, 10]"));
  CHECK_THROWS_AS(kmeans(X, 0), std::invalid_argument);
}
