// The rotation elements of a mesh (arap_energy.h): spokes and rims of a
// triangle mesh, the edges of each tetrahedron, a subset, and the pairs of
// neighbouring elements of the moving-frame term.
#include "qpreduce/deform/energy/arap_energy.h"

#include <Eigen/Dense>
#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <stdexcept>
#include <utility>
#include <vector>

namespace qpreduce::deform {

namespace {

using Vec3 = Eigen::Vector3d;

Vec3 vertex(const Vertices& V, Index i) { return V.row(i).transpose(); }

void push_edge(RotationElements& el, int i, int j, double c) {
  el.edge_i.push_back(i);
  el.edge_j.push_back(j);
  el.weight.push_back(c);
}


void check_element_index(const char* what, Index element, int v, Index n) {
  if (v < 0 || v >= n) {
    throw std::invalid_argument(
        fmt::format("{}: element {} has vertex index {} outside [0, {})", what, element, v, n));
  }
}

}  // namespace


RotationElements spokes_and_rims_elements(const Vertices& V, const Triangles& F) {
  const Index n = V.rows(), m = F.rows();
  // Faces incident to each vertex.
  std::vector<std::vector<Index>> faces_of(static_cast<size_t>(n));
  for (Index f = 0; f < m; ++f)
    for (int c = 0; c < 3; ++c) {
      check_element_index("spokes_and_rims_elements", f, F(f, c), n);
      faces_of[static_cast<size_t>(F(f, c))].push_back(f);
    }
  // Per-face half-cotangent weights of the edge opposite each corner, and areas.
  Eigen::Matrix<double, Eigen::Dynamic, 3> cot(m, 3);
  Eigen::VectorXd area(m);
  for (Index f = 0; f < m; ++f) {
    const Vec3 p[3] = {vertex(V, F(f, 0)), vertex(V, F(f, 1)), vertex(V, F(f, 2))};
    const double a2 = (p[1] - p[0]).cross(p[2] - p[0]).norm();
    const double lmax = std::max({(p[1] - p[0]).norm(), (p[2] - p[1]).norm(), (p[0] - p[2]).norm()});
    if (!(a2 > 1e-12 * lmax * lmax) || !std::isfinite(a2)) {
      throw std::invalid_argument(fmt::format(
          "spokes_and_rims_elements: triangle {} ({}, {}, {}) is degenerate (area {:.3e})", f, F(f, 0), F(f, 1),
          F(f, 2), 0.5 * a2));
    }
    area(f) = 0.5 * a2;
    for (int c = 0; c < 3; ++c) {
      const Vec3 u = p[(c + 1) % 3] - p[c], w = p[(c + 2) % 3] - p[c];
      cot(f, c) = 0.5 * u.dot(w) / a2;  // ½ cot(angle at corner c)
    }
  }
  RotationElements el;
  el.is_surface = true;
  el.measure = Eigen::VectorXd::Zero(n);
  el.normal = Vertices::Zero(n, 3);
  el.offsets.reserve(static_cast<size_t>(n) + 1);
  for (Index k = 0; k < n; ++k) {
    Vec3 normal = Vec3::Zero();
    for (Index f : faces_of[static_cast<size_t>(k)]) {
      for (int c = 0; c < 3; ++c) push_edge(el, F(f, (c + 1) % 3), F(f, (c + 2) % 3), cot(f, c));
      el.measure(k) += area(f) / 3.0;
      const Vec3 p0 = vertex(V, F(f, 0)), p1 = vertex(V, F(f, 1)), p2 = vertex(V, F(f, 2));
      normal += 0.5 * (p1 - p0).cross(p2 - p0);
    }
    if (normal.norm() > 0) el.normal.row(k) = normal.normalized().transpose();
    el.offsets.push_back(static_cast<Index>(el.weight.size()));
  }
  return el;
}

RotationElements tet_elements(const Vertices& V, const Tetrahedra& T) {
  const Index n = V.rows(), m = T.rows();
  RotationElements el;
  el.is_surface = false;
  el.measure.resize(m);
  el.offsets.reserve(static_cast<size_t>(m) + 1);
  static const int edges[6][2] = {{0, 1}, {0, 2}, {0, 3}, {1, 2}, {1, 3}, {2, 3}};
  for (Index t = 0; t < m; ++t) {
    for (int c = 0; c < 4; ++c) check_element_index("tet_elements", t, T(t, c), n);
    const Vec3 p0 = vertex(V, T(t, 0));
    Eigen::Matrix3d E;
    E.col(0) = vertex(V, T(t, 1)) - p0;
    E.col(1) = vertex(V, T(t, 2)) - p0;
    E.col(2) = vertex(V, T(t, 3)) - p0;
    const double det = E.determinant();
    const double lmax = E.colwise().norm().maxCoeff();
    if (!(std::abs(det) > 1e-12 * lmax * lmax * lmax) || !std::isfinite(det)) {
      throw std::invalid_argument(fmt::format("tet_elements: tet {} is degenerate (volume {:.3e})", t, det / 6.0));
    }
    const double vol = std::abs(det) / 6.0;
    // Gradients of the barycentric functions: rows of E⁻¹ for φ1..φ3, φ0 = −Σ.
    const Eigen::Matrix3d Einv = E.inverse();
    Eigen::Matrix<double, 4, 3> grad;
    grad.row(1) = Einv.row(0);
    grad.row(2) = Einv.row(1);
    grad.row(3) = Einv.row(2);
    grad.row(0) = -(grad.row(1) + grad.row(2) + grad.row(3));
    for (const auto& e : edges) {
      // w_ij = −vol·∇φ_i·∇φ_j = (1/6)·ℓ_kl·cot θ_kl.
      const double w = -vol * grad.row(e[0]).dot(grad.row(e[1]));
      push_edge(el, T(t, e[0]), T(t, e[1]), w);
    }
    el.measure(t) = vol;
    el.offsets.push_back(static_cast<Index>(el.weight.size()));
  }
  return el;
}

RotationElements select_elements(const RotationElements& el, const std::vector<Index>& keep) {
  RotationElements out;
  out.is_surface = el.is_surface;
  out.measure.resize(static_cast<Index>(keep.size()));
  if (el.normal.rows() > 0) out.normal.resize(static_cast<Index>(keep.size()), 3);
  out.offsets.reserve(keep.size() + 1);
  out.original.reserve(keep.size());
  Index last = -1;
  for (size_t i = 0; i < keep.size(); ++i) {
    const Index k = keep[i];
    if (k <= last || k >= el.size()) {
      throw std::invalid_argument(fmt::format("select_elements: index {} ({}) is {}", i, k,
                                              k >= el.size() ? fmt::format("not below the {} elements", el.size())
                                                             : std::string("not ascending")));
    }
    last = k;
    for (Index e = el.offsets[k]; e < el.offsets[k + 1]; ++e) push_edge(out, el.edge_i[e], el.edge_j[e], el.weight[e]);
    out.offsets.push_back(static_cast<Index>(out.weight.size()));
    out.measure(static_cast<Index>(i)) = el.measure(k);
    out.original.push_back(el.original.empty() ? k : el.original[static_cast<size_t>(k)]);
    if (el.normal.rows() > 0) out.normal.row(static_cast<Index>(i)) = el.normal.row(k);
  }
  return out;
}

std::vector<std::pair<Index, Index>> element_neighbours(const RotationElements& el) {
  std::vector<std::pair<Index, Index>> pairs;
  if (el.is_surface) {
    // Element k is vertex k (original[k] in a subset): neighbours are the
    // mesh edges between two elements present.
    std::vector<Index> element_of;  // vertex → element, −1: not kept (subsets only)
    if (!el.original.empty()) {
      Index top = 0;
      for (const Index v : el.original) top = std::max(top, v + 1);
      for (size_t e = 0; e < el.edge_i.size(); ++e) top = std::max<Index>(top, std::max(el.edge_i[e], el.edge_j[e]) + 1);
      element_of.assign(static_cast<size_t>(top), -1);
      for (Index k = 0; k < el.size(); ++k) element_of[static_cast<size_t>(el.original[static_cast<size_t>(k)])] = k;
    }
    pairs.reserve(el.edge_i.size() / 3);
    for (size_t e = 0; e < el.edge_i.size(); ++e) {
      Index i = el.edge_i[e], j = el.edge_j[e];
      if (!element_of.empty()) {
        i = element_of[static_cast<size_t>(i)];
        j = element_of[static_cast<size_t>(j)];
        if (i < 0 || j < 0) continue;
      }
      if (i != j) pairs.emplace_back(std::min(i, j), std::max(i, j));
    }
  } else {
    // Tets sharing a face: sort the (face, tet) records by face.
    struct FaceOf {
      std::array<int, 3> face;
      Index tet;
    };
    std::vector<FaceOf> faces;
    faces.reserve(static_cast<size_t>(el.size()) * 4);
    for (Index k = 0; k < el.size(); ++k) {
      std::vector<int> v;
      for (Index e = el.offsets[k]; e < el.offsets[k + 1]; ++e) {
        v.push_back(el.edge_i[e]);
        v.push_back(el.edge_j[e]);
      }
      std::sort(v.begin(), v.end());
      v.erase(std::unique(v.begin(), v.end()), v.end());
      if (v.size() != 4) continue;
      for (int skip = 0; skip < 4; ++skip) {
        FaceOf f{{0, 0, 0}, k};
        for (int c = 0, o = 0; c < 4; ++c)
          if (c != skip) f.face[static_cast<size_t>(o++)] = v[static_cast<size_t>(c)];
        faces.push_back(f);
      }
    }
    std::sort(faces.begin(), faces.end(), [](const FaceOf& a, const FaceOf& b) {
      return a.face != b.face ? a.face < b.face : a.tet < b.tet;
    });
    for (size_t a = 0; a + 1 < faces.size(); ++a)
      for (size_t b = a + 1; b < faces.size() && faces[b].face == faces[a].face; ++b)
        pairs.emplace_back(faces[a].tet, faces[b].tet);
  }
  std::sort(pairs.begin(), pairs.end());
  pairs.erase(std::unique(pairs.begin(), pairs.end()), pairs.end());
  return pairs;
}

}  // namespace qpreduce::deform
