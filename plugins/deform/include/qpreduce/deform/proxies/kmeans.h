// qpreduce::deform — k-means of points in R^dim, the last step of the
// rotational clustering (docs/proxies.md).
#pragma once

#include <qpreduce/common.h>

#include <Eigen/Core>

#include <cstdint>
#include <string>
#include <vector>

namespace qpreduce::deform {

struct KMeansOptions {
  // Seed of the k-means++ draws. The same seed gives the same labels on every
  // platform (the generator and the draws are our own, not <random>'s
  // distributions).
  std::uint64_t seed = 1;
  // Lloyd iterations at most (each: assign to the nearest centre, recompute
  // centres). 100 is far above what a well-seeded k-means needs for d ≲ 100.
  int max_iterations = 100;
  // Converged when no label changes, or when the objective Σ‖x − c‖² drops by
  // less than tolerance·objective in an iteration. (Lloyd's tail moves a few
  // boundary points per iteration for tens of iterations; Hamerly's bounds
  // make those iterations O(n), so there is little to gain by stopping early.)
  double tolerance = 1e-6;

  bool is_valid(std::string* why) const;
};

struct KMeansResult {
  std::vector<int> labels;                                                  // per point, in [0, k)
  Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> centres;  // k × dim
  double objective = 0.0;  // Σ ‖x − c_label‖²
  int iterations = 0;
  bool converged = false;
};

// k-means of the rows of `points` into exactly k non-empty clusters (an empty
// cluster is refilled with the point farthest from its centre): k-means++
// seeding, then Lloyd iterations accelerated with Hamerly's distance bounds
// (same result as plain Lloyd). Deterministic for a seed.
//
// Inputs:
//   points   n by dim, finite
//   k        number of clusters, 1 ≤ k ≤ n
//   options  seed, iteration limit and tolerance
// Returns labels (n, in [0, k)), centres (k by dim), objective, iterations.
// Throws std::invalid_argument when k < 1, k > n, points are not finite, or
// the options are invalid.
KMeansResult kmeans(const Eigen::Ref<const Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>>& points,
                    Index k, const KMeansOptions& options = {});

}  // namespace qpreduce::deform
