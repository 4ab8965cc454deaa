#include "qpreduce/deform/mesh/tet_boundary.h"

#include <algorithm>
#include <array>
#include <map>
#include <utility>
#include <vector>

namespace qpreduce::deform {

Triangles boundary_faces(const Tetrahedra& T) {
  // Outward faces of a positive tet (a, b, c, d): (a, c, b), (a, b, d), (a, d, c), (b, c, d).
  static constexpr int kFaces[4][3] = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
  std::map<std::array<int, 3>, std::pair<int, std::array<int, 3>>> faces;  // sorted corners → (count, oriented)
  for (Index t = 0; t < T.rows(); ++t)
    for (const auto& f : kFaces) {
      const std::array<int, 3> oriented{T(t, f[0]), T(t, f[1]), T(t, f[2])};
      std::array<int, 3> key = oriented;
      std::sort(key.begin(), key.end());
      auto& entry = faces[key];
      ++entry.first;
      entry.second = oriented;
    }
  std::vector<std::array<int, 3>> boundary;
  for (const auto& [key, entry] : faces)
    if (entry.first == 1) boundary.push_back(entry.second);
  Triangles F(static_cast<Index>(boundary.size()), 3);
  for (size_t i = 0; i < boundary.size(); ++i)
    for (int c = 0; c < 3; ++c) F(static_cast<Index>(i), c) = boundary[i][c];
  return F;
}

}  // namespace qpreduce::deform
