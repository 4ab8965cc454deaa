// k-means with k-means++ seeding (Arthur & Vassilvitskii 2007) and Lloyd
// iterations; see kmeans.h.
#include "qpreduce/deform/proxies/kmeans.h"

#include "proxies_internal.h"

#include <Eigen/Dense>

#include <fmt/format.h>

#include <cassert>
#include <cmath>
#include <limits>
#include <random>
#include <stdexcept>

namespace qpreduce::deform {

namespace {

using RowMatrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

// Uniform double in [0, 1) from the 53 high bits of a mt19937_64 draw. The
// engine's output sequence is fixed by the C++ standard; the distributions of
// <random> are not, so we do the conversion ourselves.
double uniform01(std::mt19937_64& rng) { return static_cast<double>(rng() >> 11) * 0x1.0p-53; }

// k-means++: the first centre uniformly at random, each next one with
// probability proportional to the squared distance to the nearest centre so
// far. When every remaining point coincides with a centre, the lowest-index
// point that is not a centre yet is taken (so k distinct indices always).
std::vector<Index> seed_plus_plus(const Eigen::Ref<const RowMatrix>& X, Index k, std::mt19937_64& rng) {
  const Index n = X.rows();
  std::vector<Index> centres;
  centres.reserve(static_cast<std::size_t>(k));
  std::vector<char> is_centre(static_cast<std::size_t>(n), 0);
  Eigen::VectorXd d2(n);
  auto add = [&](Index c) {
    centres.push_back(c);
    is_centre[c] = 1;
    for (Index i = 0; i < n; ++i) {
      const double d = (X.row(i) - X.row(c)).squaredNorm();
      d2[i] = centres.size() == 1 ? d : std::min(d2[i], d);
    }
  };
  add(std::min<Index>(static_cast<Index>(uniform01(rng) * static_cast<double>(n)), n - 1));
  while (static_cast<Index>(centres.size()) < k) {
    const double total = d2.sum();
    Index pick = -1;
    if (total > 0.0) {
      const double r = uniform01(rng) * total;
      double cumulative = 0.0;
      for (Index i = 0; i < n; ++i) {
        if (d2[i] <= 0.0) continue;
        cumulative += d2[i];
        pick = i;  // the last positive one if rounding leaves r ≥ the sum
        if (cumulative > r) break;
      }
    }
    if (pick < 0 || is_centre[pick]) {
      for (Index i = 0; i < n; ++i) {
        if (!is_centre[i]) {
          pick = i;
          break;
        }
      }
    }
    add(pick);
  }
  return centres;
}

// Lloyd iterations with Hamerly's bounds (Hamerly 2010, "Making k-means even
// faster"): the same assignments as plain Lloyd, but a point whose distance to
// its centre (upper bound u_i) is below both half the distance from that
// centre to the nearest other one (s_a) and a lower bound l_i on the distance
// to any other centre cannot change cluster, so it costs O(1) instead of
// O(k·dim). Late iterations, where few points move, become almost free.
struct Bounds {
  std::vector<int> labels;
  Eigen::VectorXd upper, lower;  // distances (not squared)
};

// Distance to the nearest and second-nearest centre (ties: lowest index).
void nearest_two(const Eigen::Ref<const RowMatrix>& X, const RowMatrix& C, Index i, Index* best, double* d1,
                 double* d2) {
  *best = 0;
  *d1 = std::numeric_limits<double>::infinity();
  *d2 = std::numeric_limits<double>::infinity();
  for (Index c = 0; c < C.rows(); ++c) {
    const double d = (X.row(i) - C.row(c)).norm();
    if (d < *d1) {
      *d2 = *d1;
      *d1 = d;
      *best = c;
    } else if (d < *d2) {
      *d2 = d;
    }
  }
}

// Exact bounds. reassign: move every point to its nearest centre (returns
// the number of labels that changed); otherwise keep labels.
Index exact_bounds(const Eigen::Ref<const RowMatrix>& X, const RowMatrix& C, Bounds& b, bool reassign) {
  Index changed = 0;
  for (Index i = 0; i < X.rows(); ++i) {
    if (reassign) {
      Index best;
      nearest_two(X, C, i, &best, &b.upper[i], &b.lower[i]);
      if (b.labels[i] != best) {
        b.labels[i] = static_cast<int>(best);
        ++changed;
      }
    } else {
      b.upper[i] = (X.row(i) - C.row(b.labels[i])).norm();
      double other = std::numeric_limits<double>::infinity();
      for (Index c = 0; c < C.rows(); ++c) {
        if (c != b.labels[i]) other = std::min(other, (X.row(i) - C.row(c)).norm());
      }
      b.lower[i] = other;
    }
  }
  return changed;
}

// One Hamerly assignment step; returns the number of labels that changed.
Index hamerly_assign(const Eigen::Ref<const RowMatrix>& X, const RowMatrix& C, Bounds& b) {
  const Index k = C.rows();
  Eigen::VectorXd half_gap = Eigen::VectorXd::Constant(k, std::numeric_limits<double>::infinity());
  for (Index c = 0; c < k; ++c) {
    for (Index e = c + 1; e < k; ++e) {
      const double d = 0.5 * (C.row(c) - C.row(e)).norm();
      half_gap[c] = std::min(half_gap[c], d);
      half_gap[e] = std::min(half_gap[e], d);
    }
  }
  Index changed = 0;
  for (Index i = 0; i < X.rows(); ++i) {
    const int a = b.labels[i];
    const double bound = std::max(half_gap[a], b.lower[i]);
    if (b.upper[i] <= bound) continue;
    b.upper[i] = (X.row(i) - C.row(a)).norm();
    if (b.upper[i] <= bound) continue;
    Index best;
    nearest_two(X, C, i, &best, &b.upper[i], &b.lower[i]);
    if (best != a) {
      b.labels[i] = static_cast<int>(best);
      ++changed;
    }
  }
  return changed;
}

// Refills empty clusters: each takes the point farthest from its centre among
// clusters that have more than one point (lowest index on ties). Returns true
// when it moved anything (the caller then recomputes the bounds).
bool fill_empty(const Eigen::Ref<const RowMatrix>& X, RowMatrix& C, Bounds& b) {
  const Index k = C.rows();
  std::vector<Index> size(static_cast<std::size_t>(k), 0);
  for (int l : b.labels) ++size[l];
  bool moved = false;
  for (Index c = 0; c < k; ++c) {
    if (size[c] > 0) continue;
    Index far = -1;
    double far_d = -1.0;
    for (Index i = 0; i < X.rows(); ++i) {
      if (size[b.labels[i]] < 2) continue;
      const double d = (X.row(i) - C.row(b.labels[i])).squaredNorm();
      if (d > far_d) {
        far_d = d;
        far = i;
      }
    }
    assert(far >= 0);  // k ≤ n guarantees a cluster with two points
    --size[b.labels[far]];
    b.labels[far] = static_cast<int>(c);
    ++size[c];
    C.row(c) = X.row(far);
    moved = true;
  }
  return moved;
}

// Centres = means of their points (an empty cluster keeps its centre);
// returns how far each centre moved.
Eigen::VectorXd update_centres(const Eigen::Ref<const RowMatrix>& X, const std::vector<int>& labels, RowMatrix& C) {
  const Index k = C.rows();
  Eigen::VectorXd count = Eigen::VectorXd::Zero(k);
  RowMatrix sum = RowMatrix::Zero(k, X.cols());
  for (Index i = 0; i < X.rows(); ++i) {
    sum.row(labels[i]) += X.row(i);
    count[labels[i]] += 1.0;
  }
  Eigen::VectorXd moved = Eigen::VectorXd::Zero(k);
  for (Index c = 0; c < k; ++c) {
    if (count[c] == 0.0) continue;
    const Eigen::RowVectorXd next = sum.row(c) / count[c];
    moved[c] = (next - C.row(c)).norm();
    C.row(c) = next;
  }
  return moved;
}

double objective_of(const Eigen::Ref<const RowMatrix>& X, const RowMatrix& C, const std::vector<int>& labels) {
  double total = 0.0;
  for (Index i = 0; i < X.rows(); ++i) total += (X.row(i) - C.row(labels[i])).squaredNorm();
  return total;
}

}  // namespace

bool KMeansOptions::is_valid(std::string* why) const {
  const auto fail = [why](const char* reason) { return detail::reject(why, reason); };
  if (max_iterations < 0) return fail("KMeansOptions: max_iterations must be ≥ 0");
  if (!(tolerance >= 0.0)) return fail("KMeansOptions: tolerance must be ≥ 0");
  return true;
}

KMeansResult kmeans(const Eigen::Ref<const RowMatrix>& X, Index k, const KMeansOptions& options) {
  std::string why;
  if (!options.is_valid(&why)) throw std::invalid_argument("kmeans: " + why);
  const Index n = X.rows();
  if (k < 1 || k > n) {
    throw std::invalid_argument(fmt::format("kmeans: cluster count must lie in [1, {}] (the point count), got {}", n, k));
  }
  if (!X.allFinite()) throw std::invalid_argument("kmeans: points contain NaN or infinite entries");

  std::mt19937_64 rng(options.seed);
  const std::vector<Index> seeds = seed_plus_plus(X, k, rng);
  KMeansResult out;
  out.centres.resize(k, X.cols());
  for (Index c = 0; c < k; ++c) out.centres.row(c) = X.row(seeds[c]);
  Bounds b;
  b.labels.assign(static_cast<std::size_t>(n), -1);
  b.upper.resize(n);
  b.lower.resize(n);
  exact_bounds(X, out.centres, b, true);
  if (fill_empty(X, out.centres, b)) exact_bounds(X, out.centres, b, false);
  double objective = objective_of(X, out.centres, b.labels);

  for (int it = 0; it < options.max_iterations; ++it) {
    const Eigen::VectorXd moved = update_centres(X, b.labels, out.centres);
    // Bounds after the move: u_i grows by its centre's move, l_i shrinks by
    // the largest move of any other centre.
    Index first = 0;
    moved.maxCoeff(&first);
    double second = 0.0;
    for (Index c = 0; c < k; ++c) {
      if (c != first) second = std::max(second, moved[c]);
    }
    for (Index i = 0; i < n; ++i) {
      b.upper[i] += moved[b.labels[i]];
      b.lower[i] -= b.labels[i] == first ? second : moved[first];
    }
    const Index changed = hamerly_assign(X, out.centres, b);
    if (fill_empty(X, out.centres, b)) exact_bounds(X, out.centres, b, false);
    const double next = objective_of(X, out.centres, b.labels);
    out.iterations = it + 1;
    const bool small_decrease = objective - next <= options.tolerance * next;
    objective = next;
    if (changed == 0 || small_decrease) {
      out.converged = true;
      break;
    }
  }
  // Centres consistent with the final labels.
  update_centres(X, b.labels, out.centres);
  out.labels = std::move(b.labels);
  out.objective = objective_of(X, out.centres, out.labels);
  return out;
}

}  // namespace qpreduce::deform
