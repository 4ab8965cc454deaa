#include "qpreduce/deform/mesh/geometry.h"

#include <Eigen/Dense>
#include <Eigen/SparseCore>

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <stdexcept>

namespace qpreduce::deform {

namespace {

using Vec3 = Eigen::Vector3d;
using Triplet = Eigen::Triplet<double, int>;

void check_vertices(const char* what, const VerticesRef& V) {
  if (V.cols() != 3) {
    throw std::invalid_argument(fmt::format("{}: V must have 3 columns: expected 3, got {}", what, V.cols()));
  }
  if (!V.allFinite()) {
    throw std::invalid_argument(fmt::format("{}: V contains NaN or infinite entries", what));
  }
}

// Checks column count, index range and repeated corners of every element.
void check_elements(const char* what, const char* kind, Index n, const ElementsRef& E, Index corners) {
  if (E.cols() != corners) {
    throw std::invalid_argument(
        fmt::format("{}: {} must have {} columns: expected {}, got {}", what, kind, corners, corners, E.cols()));
  }
  for (Index e = 0; e < E.rows(); ++e) {
    for (Index a = 0; a < corners; ++a) {
      const int v = E(e, a);
      if (v < 0 || v >= n) {
        throw std::invalid_argument(fmt::format("{}: {} {} has vertex index {} outside [0, {})", what, kind, e, v, n));
      }
      for (Index b = 0; b < a; ++b) {
        if (E(e, b) == v) {
          throw std::invalid_argument(
              fmt::format("{}: {} {} is degenerate (vertex {} repeated)", what, kind, e, v));
        }
      }
    }
  }
}

Vec3 vertex_at(const VerticesRef& V, int i) { return V.row(i).transpose(); }

// Twice the area of triangle f, after the degeneracy check.
double checked_double_area(const char* what, const VerticesRef& V, const ElementsRef& F, Index f,
                           double tolerance, Vec3* cross = nullptr) {
  const Vec3 a = vertex_at(V, F(f, 0)), b = vertex_at(V, F(f, 1)), c = vertex_at(V, F(f, 2));
  const Vec3 n = (b - a).cross(c - a);
  const double twice_area = n.norm();
  const double lmax2 = std::max({(b - a).squaredNorm(), (c - b).squaredNorm(), (a - c).squaredNorm()});
  if (!std::isfinite(twice_area) || !(twice_area > tolerance * lmax2)) {
    throw std::invalid_argument(fmt::format(
        "{}: face {} is degenerate (area {:.3e}, longest edge {:.3e})", what, f, 0.5 * twice_area, std::sqrt(lmax2)));
  }
  if (cross) *cross = n;
  return twice_area;
}

// Edge matrix [b − a, c − a, d − a] of tet t and 6·|volume|, after the check.
double checked_six_volume(const char* what, const VerticesRef& V, const ElementsRef& T, Index t,
                          double tolerance, Eigen::Matrix3d* edges) {
  const Vec3 a = vertex_at(V, T(t, 0));
  Eigen::Matrix3d E;
  for (int k = 0; k < 3; ++k) E.col(k) = vertex_at(V, T(t, k + 1)) - a;
  double lmax2 = 0.0;
  for (int i = 0; i < 4; ++i) {
    for (int j = i + 1; j < 4; ++j)
      lmax2 = std::max(lmax2, (vertex_at(V, T(t, i)) - vertex_at(V, T(t, j))).squaredNorm());
  }
  const double six_volume = std::abs(E.determinant());
  if (!std::isfinite(six_volume) || !(six_volume > tolerance * lmax2 * std::sqrt(lmax2))) {
    throw std::invalid_argument(fmt::format("{}: tet {} is degenerate (volume {:.3e}, longest edge {:.3e})", what,
                                            t, six_volume / 6.0, std::sqrt(lmax2)));
  }
  if (edges) *edges = E;
  return six_volume;
}

// Assembles L from off-diagonal weight triplets (i, j, w_ij), each unordered
// pair given once per element: L_ij = L_ji = −w, diagonal = Σ w so rows sum
// to zero up to the rounding of that one sum.
SparseMatrix<double> assemble_laplacian(Index n, const std::vector<Triplet>& weights) {
  std::vector<Triplet> entries;
  entries.reserve(4 * weights.size());
  for (const Triplet& t : weights) {
    entries.emplace_back(t.row(), t.col(), -t.value());
    entries.emplace_back(t.col(), t.row(), -t.value());
    entries.emplace_back(t.row(), t.row(), t.value());
    entries.emplace_back(t.col(), t.col(), t.value());
  }
  SparseMatrix<double> L(n, n);
  L.setFromTriplets(entries.begin(), entries.end());
  L.makeCompressed();
  return L;
}

// Lumped mass: each element's measure split equally among its corners.
Eigen::VectorXd spread_to_corners(Index n, const ElementsRef& E, const Eigen::VectorXd& measures) {
  Eigen::VectorXd mass = Eigen::VectorXd::Zero(n);
  const double share = 1.0 / static_cast<double>(E.cols());
  for (Index e = 0; e < E.rows(); ++e) {
    for (Index c = 0; c < E.cols(); ++c) mass[E(e, c)] += share * measures[e];
  }
  return mass;
}

// Checks V and E (`corners` columns, `kind` in messages) and returns
// value(e) for each element e.
template <typename PerElement>
Eigen::VectorXd per_element(const char* what, const char* kind, int corners, const VerticesRef& V,
                            const ElementsRef& E, PerElement value) {
  check_vertices(what, V);
  check_elements(what, kind, V.rows(), E, corners);
  Eigen::VectorXd out(E.rows());
  for (Index e = 0; e < E.rows(); ++e) out[e] = value(e);
  return out;
}

// Checks V and E (`corners` columns, `kind` in messages), lets
// add_weights(e, weights) append the off-diagonal weights w_ij of element e
// (at most `per_element` of them) and assembles the Laplacian.
template <typename AddWeights>
SparseMatrix<double> laplacian_from_elements(const char* what, const char* kind, int corners, int per_element,
                                             const VerticesRef& V, const ElementsRef& E, AddWeights add_weights) {
  check_vertices(what, V);
  check_elements(what, kind, V.rows(), E, corners);
  std::vector<Triplet> weights;
  weights.reserve(per_element * E.rows());
  for (Index e = 0; e < E.rows(); ++e) add_weights(e, weights);
  return assemble_laplacian(V.rows(), weights);
}

}  // namespace

SparseMatrix<double> cotangent_laplacian(const VerticesRef& V, const ElementsRef& F, double tolerance) {
  const char* what = "cotangent_laplacian";
  return laplacian_from_elements(what, "face", 3, 3, V, F, [&](Index f, std::vector<Triplet>& weights) {
    const double twice_area = checked_double_area(what, V, F, f, tolerance);
    for (int c = 0; c < 3; ++c) {
      // cot of the angle at corner c = (u·v)/|u×v|, u, v the two edges leaving it;
      // it weighs the opposite edge (i, j).
      const int o = F(f, c), i = F(f, (c + 1) % 3), j = F(f, (c + 2) % 3);
      const Vec3 u = vertex_at(V, i) - vertex_at(V, o), v = vertex_at(V, j) - vertex_at(V, o);
      weights.emplace_back(i, j, 0.5 * u.dot(v) / twice_area);
    }
  });
}

Eigen::VectorXd face_areas(const VerticesRef& V, const ElementsRef& F, double tolerance) {
  const char* what = "face_areas";
  return per_element(what, "face", 3, V, F,
                     [&](Index f) { return 0.5 * checked_double_area(what, V, F, f, tolerance); });
}

Eigen::VectorXd lumped_mass(const VerticesRef& V, const ElementsRef& F, double tolerance) {
  return spread_to_corners(V.rows(), F, face_areas(V, F, tolerance));
}

Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor> face_normals(const VerticesRef& V, const ElementsRef& F,
                                                                       double tolerance) {
  const char* what = "face_normals";
  check_vertices(what, V);
  check_elements(what, "face", V.rows(), F, 3);
  Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor> N(F.rows(), 3);
  for (Index f = 0; f < F.rows(); ++f) {
    Vec3 cross;
    const double twice_area = checked_double_area(what, V, F, f, tolerance, &cross);
    N.row(f) = (cross / twice_area).transpose();
  }
  return N;
}

Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor> vertex_normals(const VerticesRef& V,
                                                                         const ElementsRef& F, double tolerance) {
  const char* what = "vertex_normals";
  check_vertices(what, V);
  check_elements(what, "face", V.rows(), F, 3);
  Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor> N =
      Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>::Zero(V.rows(), 3);
  for (Index f = 0; f < F.rows(); ++f) {
    Vec3 cross;  // = 2·area·n_f
    checked_double_area(what, V, F, f, tolerance, &cross);
    for (int c = 0; c < 3; ++c) N.row(F(f, c)) += cross.transpose();
  }
  for (Index v = 0; v < N.rows(); ++v) {
    const double norm = N.row(v).norm();
    if (norm > 0.0) N.row(v) /= norm;
  }
  return N;
}

SparseMatrix<double> cotangent_laplacian_tets(const VerticesRef& V, const ElementsRef& T, double tolerance) {
  const char* what = "cotangent_laplacian_tets";
  return laplacian_from_elements(what, "tet", 4, 6, V, T, [&](Index t, std::vector<Triplet>& weights) {
    Eigen::Matrix3d E;
    const double six_volume = checked_six_volume(what, V, T, t, tolerance, &E);
    // Rows of E⁻¹ are ∇φ_b, ∇φ_c, ∇φ_d; ∇φ_a = −(their sum). K_ij = vol·∇φ_i·∇φ_j,
    // and w_ij = −K_ij = (1/6)·l_kl·cot θ_kl.
    Eigen::Matrix<double, 4, 3> G;
    G.bottomRows<3>() = E.inverse();
    G.row(0) = -G.bottomRows<3>().colwise().sum();
    const double volume = six_volume / 6.0;
    for (int i = 0; i < 4; ++i) {
      for (int j = i + 1; j < 4; ++j) weights.emplace_back(T(t, i), T(t, j), -volume * G.row(i).dot(G.row(j)));
    }
  });
}

Eigen::VectorXd tet_volumes(const VerticesRef& V, const ElementsRef& T, double tolerance) {
  const char* what = "tet_volumes";
  return per_element(what, "tet", 4, V, T,
                     [&](Index t) { return checked_six_volume(what, V, T, t, tolerance, nullptr) / 6.0; });
}

Eigen::VectorXd lumped_mass_tets(const VerticesRef& V, const ElementsRef& T, double tolerance) {
  return spread_to_corners(V.rows(), T, tet_volumes(V, T, tolerance));
}

void laplacian_and_mass(const VerticesRef& V, const ElementsRef& E, SparseMatrix<double>* L, Eigen::VectorXd* mass,
                        double tolerance) {
  if (E.cols() == 3) {
    if (L) *L = cotangent_laplacian(V, E, tolerance);
    if (mass) *mass = lumped_mass(V, E, tolerance);
  } else if (E.cols() == 4) {
    if (L) *L = cotangent_laplacian_tets(V, E, tolerance);
    if (mass) *mass = lumped_mass_tets(V, E, tolerance);
  } else {
    throw std::invalid_argument(
        fmt::format("laplacian_and_mass: elements must be triangles (3 columns) or tets (4), got {} columns", E.cols()));
  }
}

Eigen::VectorXd element_measures(const VerticesRef& V, const ElementsRef& E, double tolerance) {
  if (E.cols() == 3) return face_areas(V, E, tolerance);
  if (E.cols() == 4) return tet_volumes(V, E, tolerance);
  throw std::invalid_argument(
      fmt::format("element_measures: elements must be triangles (3 columns) or tets (4), got {} columns", E.cols()));
}

double bounding_box_diagonal(const VerticesRef& V) {
  check_vertices("bounding_box_diagonal", V);
  if (V.rows() == 0) throw std::invalid_argument("bounding_box_diagonal: V has no vertices");
  return (V.colwise().maxCoeff() - V.colwise().minCoeff()).norm();
}

std::vector<std::vector<Index>> MeshComponents::vertex_lists() const {
  std::vector<std::vector<Index>> lists(static_cast<std::size_t>(count));
  for (std::size_t v = 0; v < vertex_component.size(); ++v) lists[vertex_component[v]].push_back(static_cast<Index>(v));
  return lists;
}

MeshComponents connected_components(Index n, const ElementsRef& E) {
  if (n < 0) throw std::invalid_argument("connected_components: negative vertex count");
  if (E.cols() < 1 && E.rows() > 0) throw std::invalid_argument("connected_components: elements have no corners");
  for (Index e = 0; e < E.rows(); ++e) {
    for (Index a = 0; a < E.cols(); ++a) {
      if (E(e, a) < 0 || E(e, a) >= n) {
        throw std::invalid_argument(fmt::format("connected_components: element {} has vertex index {} outside [0, {})",
                                                e, E(e, a), n));
      }
    }
  }
  // Union–find over vertices, with path halving and union by index (the root
  // is the smaller index, so the result does not depend on element order).
  std::vector<int> parent(static_cast<std::size_t>(n));
  std::iota(parent.begin(), parent.end(), 0);
  auto find = [&parent](int v) {
    while (parent[v] != v) {
      parent[v] = parent[parent[v]];
      v = parent[v];
    }
    return v;
  };
  std::vector<char> referenced(static_cast<std::size_t>(n), 0);
  for (Index e = 0; e < E.rows(); ++e) {
    referenced[E(e, 0)] = 1;
    for (Index a = 1; a < E.cols(); ++a) {
      referenced[E(e, a)] = 1;
      const int r0 = find(E(e, 0)), r1 = find(E(e, a));
      if (r0 != r1) parent[std::max(r0, r1)] = std::min(r0, r1);
    }
  }
  MeshComponents out;
  out.vertex_component.assign(static_cast<std::size_t>(n), -1);
  out.element_component.resize(static_cast<std::size_t>(E.rows()));
  std::vector<int> id_of_root(static_cast<std::size_t>(n), -1);
  int next = 0;
  for (Index e = 0; e < E.rows(); ++e) {
    const int r = find(E(e, 0));
    if (id_of_root[r] < 0) id_of_root[r] = next++;
    out.element_component[e] = id_of_root[r];
  }
  out.element_components = next;
  for (Index v = 0; v < n; ++v) {
    if (referenced[v]) {
      out.vertex_component[v] = id_of_root[find(static_cast<int>(v))];
    } else {
      out.vertex_component[v] = next++;
      out.unreferenced.push_back(v);
    }
  }
  out.count = next;
  return out;
}

}  // namespace qpreduce::deform
