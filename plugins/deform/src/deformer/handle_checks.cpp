#include "handle_checks.h"

#include <qpreduce/checks.h>

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace qpreduce::deform::detail {

void check_mesh_elements(const DeformableMesh& mesh, const char* who) {
  const bool tet = mesh.is_tet();
  if (tet == (mesh.F.rows() > 0)) {
    throw std::invalid_argument(fmt::format("{}: give exactly one of F (surface) and T (tetrahedra)", who));
  }
  if (tet) {
    check_mesh(who, TetMesh{mesh.V, mesh.T, {}});
  } else {
    check_mesh(who, TriangleMesh{mesh.V, mesh.F});
  }
}

void check_patch_labels(const DeformableMesh& mesh, const char* who) {
  if (mesh.patch_of_vertex.empty()) return;
  const Index n = mesh.V.rows();
  check_size(fmt::format("{}: patch_of_vertex size", who).c_str(), n, static_cast<Index>(mesh.patch_of_vertex.size()));
  for (Index v = 0; v < n; ++v) {
    const int p = mesh.patch_of_vertex[v];
    if (p < -1 || p >= static_cast<int>(mesh.patch_types.size())) {
      throw std::invalid_argument(fmt::format("{}: vertex {} has patch {} outside [-1, {})", who, v, p,
                                              mesh.patch_types.size()));
    }
  }
}

void check_handles(const Handles& handles, Index n, const std::vector<PatchType>& patch_types) {
  for (size_t h = 0; h < handles.points.size(); ++h) {
    const PointHandle& ph = handles.points[h];
    if (ph.vertices.empty()) throw std::invalid_argument(fmt::format("point handle {}: no vertex", h));
    if (!ph.weights.empty() && ph.weights.size() != ph.vertices.size()) {
      throw std::invalid_argument(fmt::format("point handle {}: {} weights for {} vertices", h, ph.weights.size(),
                                              ph.vertices.size()));
    }
    if (ph.weights.empty() && ph.vertices.size() != 1) {
      throw std::invalid_argument(fmt::format("point handle {}: a group of {} vertices needs weights", h,
                                              ph.vertices.size()));
    }
    if (!ph.weights.empty() && std::all_of(ph.weights.begin(), ph.weights.end(), [](double w) { return w == 0.0; })) {
      throw std::invalid_argument(
          fmt::format("point handle {}: every weight is 0: the handle would hold no point", h));
    }
    for (size_t i = 0; i < ph.vertices.size(); ++i) {
      const Index v = ph.vertices[i];
      if (v < 0 || v >= n) throw std::invalid_argument(fmt::format("point handle {}: vertex {} outside [0, {})", h, v, n));
      if (!ph.weights.empty() && !std::isfinite(ph.weights[i])) {
        throw std::invalid_argument(fmt::format("point handle {}: weight {} is not finite", h, i));
      }
    }
  }
  const Index s = static_cast<Index>(patch_types.size());
  std::vector<char> prescribed(static_cast<size_t>(s), 0);
  for (Index p : handles.patches) {
    if (p < 0 || p >= s) throw std::invalid_argument(fmt::format("handle patch {} outside [0, {})", p, s));
    if (patch_types[p] == PatchType::Fixed) {
      throw std::invalid_argument(fmt::format("patch {} is Fixed: it is always held at the rest pose", p));
    }
    if (prescribed[p]) throw std::invalid_argument(fmt::format("patch {} is prescribed twice", p));
    prescribed[p] = 1;
  }
}

}  // namespace qpreduce::deform::detail
