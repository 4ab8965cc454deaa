#include "orientation.h"

#include <algorithm>
#include <cstdint>

namespace qpreduce::deform {

namespace {

// True when triangle t runs from a to b (b follows a in its corner order).
bool runs_from(const ElementsRef& F, Index t, Index a, Index b) {
  for (int k = 0; k < 3; ++k) {
    if (F(t, k) == a) return F(t, (k + 1) % 3) == b;
  }
  return false;
}

}  // namespace

OrientationReport triangle_orientation(const ElementsRef& F, const std::vector<SharedEdge>& shared, Index max_listed) {
  OrientationReport r;
  const Index m = F.rows();
  // Adjacency across the shared edges (compressed rows): the neighbour and
  // whether the pair disagrees (both run the edge the same way).
  std::vector<Index> start(static_cast<size_t>(m) + 1, 0);
  for (const SharedEdge& e : shared) {
    ++start[static_cast<size_t>(e.first) + 1];
    ++start[static_cast<size_t>(e.second) + 1];
  }
  for (Index t = 0; t < m; ++t) start[t + 1] += start[t];
  std::vector<std::pair<Index, bool>> next(static_cast<size_t>(start[m]));
  std::vector<Index> fill(start.begin(), start.end() - 1);
  for (const SharedEdge& e : shared) {
    const bool first_forward = runs_from(F, e.first, e.a, e.b);
    const bool disagree = first_forward == runs_from(F, e.second, e.a, e.b);
    if (disagree && r.disagreeing_edges++ == 0) {
      r.edge = first_forward ? std::array<Index, 2>{e.a, e.b} : std::array<Index, 2>{e.b, e.a};
      r.example = std::min(e.first, e.second);
      r.partner = std::max(e.first, e.second);
    }
    next[fill[e.first]++] = {e.second, disagree};
    next[fill[e.second]++] = {e.first, disagree};
  }
  if (r.disagreeing_edges == 0) return r;

  // Breadth-first over each component from its lowest triangle: class 0 is
  // oriented as that triangle, class 1 against it.
  std::vector<std::int8_t> cls(static_cast<size_t>(m), -1);
  std::vector<Index> queue, flipped;
  for (Index seed = 0; seed < m; ++seed) {
    if (cls[seed] >= 0) continue;
    queue.assign(1, seed);
    cls[seed] = 0;
    Index against = 0;
    for (size_t head = 0; head < queue.size(); ++head) {
      const Index t = queue[head];
      against += cls[t];
      for (Index k = start[t]; k < start[t + 1]; ++k) {
        const auto [u, disagree] = next[k];
        const std::int8_t want = static_cast<std::int8_t>(cls[t] ^ (disagree ? 1 : 0));
        if (cls[u] < 0) {
          cls[u] = want;
          queue.push_back(u);
        } else if (cls[u] != want) {
          r.non_orientable = true;
        }
      }
    }
    const Index size = static_cast<Index>(queue.size());
    const std::int8_t flip = 2 * against <= size ? 1 : 0;  // the smaller class
    for (const Index t : queue) {
      if (cls[t] == flip) flipped.push_back(t);
    }
  }
  r.flipped = static_cast<Index>(flipped.size());
  std::sort(flipped.begin(), flipped.end());
  flipped.resize(static_cast<size_t>(std::min<Index>(max_listed, r.flipped)));
  r.first_flipped = std::move(flipped);
  return r;
}

}  // namespace qpreduce::deform
