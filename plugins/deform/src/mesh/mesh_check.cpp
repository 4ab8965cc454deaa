#include "qpreduce/deform/mesh/mesh_check.h"

#include "finding_builder.h"
#include "orientation.h"

#include <qpreduce/util/timer.h>

#include <Eigen/Geometry>  // cross

#include <fmt/format.h>
#include <fmt/ranges.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <numeric>
#include <stdexcept>
#include <tuple>

namespace qpreduce::deform {

const char* to_string(CheckSeverity severity) { return severity == CheckSeverity::Error ? "error" : "warning"; }

const char* to_string(MeshDefect defect) {
  switch (defect) {
    case MeshDefect::NoVertices: return "no_vertices";
    case MeshDefect::NoElements: return "no_elements";
    case MeshDefect::NonFiniteCoordinate: return "non_finite_coordinate";
    case MeshDefect::CoordinateOverflow: return "coordinate_overflow";
    case MeshDefect::IndexOutOfRange: return "index_out_of_range";
    case MeshDefect::DegenerateElement: return "degenerate_element";
    case MeshDefect::FarUnreferencedVertex: return "far_unreferenced_vertex";
    case MeshDefect::UnanchoredComponent: return "unanchored_component";
    case MeshDefect::NearDegenerateElement: return "near_degenerate_element";
    case MeshDefect::InvertedTet: return "inverted_tet";
    case MeshDefect::InconsistentOrientation: return "inconsistent_orientation";
    case MeshDefect::DuplicateVertex: return "duplicate_vertex";
    case MeshDefect::UnreferencedVertex: return "unreferenced_vertex";
    case MeshDefect::NonManifoldEdge: return "non_manifold_edge";
    case MeshDefect::NonManifoldFace: return "non_manifold_face";
    case MeshDefect::NonManifoldVertex: return "non_manifold_vertex";
  }
  return "unknown";
}

const char* to_string(MeshCheckStatus status) {
  switch (status) {
    case MeshCheckStatus::NotRun: return "not run";
    case MeshCheckStatus::Clean: return "clean";
    case MeshCheckStatus::Warnings: return "warnings";
    case MeshCheckStatus::Errors: return "errors";
  }
  return "unknown";
}

bool MeshCheckOptions::is_valid(std::string* why) const {
  const auto fail = [&](const std::string& reason) {
    if (why) *why = reason;
    return false;
  };
  const std::pair<double, const char*> tolerances[] = {{degenerate_tolerance, "degenerate_tolerance"},
                                                       {near_degenerate_quality, "near_degenerate_quality"},
                                                       {duplicate_distance, "duplicate_distance"},
                                                       {far_distance, "far_distance"},
                                                       {max_coordinate, "max_coordinate"}};
  for (const auto& [value, name] : tolerances)
    if (!(value >= 0.0) || !std::isfinite(value))
      return fail(fmt::format("{} must be finite and at least 0, got {:g}", name, value));
  if (max_listed < 1) return fail(fmt::format("max_listed must be at least 1, got {}", max_listed));
  return true;
}

bool MeshCheckSummary::has_errors() const { return first(CheckSeverity::Error) != nullptr; }
bool MeshCheckSummary::has_warnings() const { return first(CheckSeverity::Warning) != nullptr; }

const MeshFinding* MeshCheckSummary::first(CheckSeverity severity) const {
  for (const MeshFinding& f : findings)
    if (f.severity == severity) return &f;
  return nullptr;
}

namespace {

// 1204 → "1,204".
using Row3 = Eigen::RowVector3d;

// What the steps share.
struct Inputs {
  Inputs(const VerticesRef& V_, const ElementsRef& E_, const std::vector<char>& anchored_, const MeshCheckOptions& o_)
      : V(V_), E(E_), anchored(anchored_), o(o_), n(V_.rows()), m(E_.rows()), p(static_cast<int>(E_.cols())) {}
  const VerticesRef& V;
  const ElementsRef& E;
  const std::vector<char>& anchored;
  const MeshCheckOptions& o;
  Index n = 0, m = 0;
  int p = 0;                      // corners per element
  std::vector<char> measurable;   // finite and within max_coordinate
  std::vector<char> referenced;   // used by an element
  std::vector<char> topological;  // element with distinct corners
  const char* element() const { return p == 3 ? "triangle" : "tet"; }
};

// Non-finite and overflowing coordinates; fills in.measurable.
void check_coordinates(Inputs& in, std::vector<MeshFinding>* out) {
  FindingBuilder nonfinite(MeshDefect::NonFiniteCoordinate, CheckSeverity::Error, "vertex", in.o.max_listed);
  FindingBuilder overflow(MeshDefect::CoordinateOverflow, CheckSeverity::Error, "vertex", in.o.max_listed);
  in.measurable.assign(static_cast<size_t>(in.n), 1);
  for (Index v = 0; v < in.n; ++v) {
    const Row3 x = in.V.row(v);
    const auto at = [&x] { return fmt::format("({:g}, {:g}, {:g})", x(0), x(1), x(2)); };
    if (!x.allFinite()) {
      in.measurable[v] = 0;
      if (nonfinite.add({v})) nonfinite.sentence(fmt::format("vertex {} at {} has a non-finite coordinate", v, at()));
    } else if (!(x.cwiseAbs().maxCoeff() <= in.o.max_coordinate)) {
      in.measurable[v] = 0;
      if (overflow.add({v}))
        overflow.sentence(fmt::format("vertex {} at {}: coordinates beyond {:g} overflow in the energy", v, at(),
                                      in.o.max_coordinate));
    }
  }
  nonfinite.finish(out);
  overflow.finish(out);
}

// Corner indices outside [0, n). True when all are inside.
bool check_indices(const Inputs& in, std::vector<MeshFinding>* out) {
  FindingBuilder range(MeshDefect::IndexOutOfRange, CheckSeverity::Error, in.element(), in.o.max_listed);
  for (Index e = 0; e < in.m; ++e)
    for (int k = 0; k < in.p; ++k) {
      const int v = in.E(e, k);
      if (v >= 0 && v < in.n) continue;
      if (range.add({e}))
        range.sentence(fmt::format("{} {} has corner {} = {}, outside the {} vertices [0, {})", in.element(), e, k, v,
                                   grouped(in.n), in.n));
      break;
    }
  const bool ok = range.count() == 0;
  range.finish(out);
  return ok;
}

// Referenced vertices, the elements with distinct corners, and the bounding
// box of the referenced measurable vertices.
void scan_references(Inputs& in, MeshCheckSummary* s) {
  in.referenced.assign(static_cast<size_t>(in.n), 0);
  in.topological.assign(static_cast<size_t>(in.m), 1);
  for (Index e = 0; e < in.m; ++e)
    for (int k = 0; k < in.p; ++k) {
      in.referenced[in.E(e, k)] = 1;
      for (int l = 0; l < k; ++l)
        if (in.E(e, k) == in.E(e, l)) in.topological[e] = 0;
    }
  Row3 lo = Row3::Constant(HUGE_VAL), hi = Row3::Constant(-HUGE_VAL);
  for (Index v = 0; v < in.n; ++v)
    if (in.referenced[v] && in.measurable[v]) {
      lo = lo.cwiseMin(in.V.row(v));
      hi = hi.cwiseMax(in.V.row(v));
    }
  if (lo(0) <= hi(0)) {
    s->box_min = lo.transpose();
    s->box_max = hi.transpose();
    s->diagonal = (hi - lo).norm();
  }
}

// "3, 8, 9" for element e.
std::string corners_of(const Inputs& in, Index e) {
  return fmt::format("{}", fmt::join(in.E.row(e).data(), in.E.row(e).data() + in.p, ", "));
}

// The measures of one element with distinct, measurable corners.
struct ElementShape {
  double shortest2 = HUGE_VAL, longest2 = 0.0;  // squared edge lengths
  double measure = 0.0;  // 2·area (triangles) or 6·|volume| (tets)
  double scale = 0.0;    // ℓ²_max (triangles) or ℓ³_max (tets): the degenerate rule is measure ≤ tol·scale
  double quality = 0.0;  // 1 for the regular element
  double det = 0.0;      // tets: det[b − a, c − a, d − a]
};

ElementShape element_shape(const Inputs& in, Index e) {
  ElementShape q;
  for (int k = 0; k < in.p; ++k)
    for (int l = k + 1; l < in.p; ++l) {
      const double l2 = (in.V.row(in.E(e, k)) - in.V.row(in.E(e, l))).squaredNorm();
      q.longest2 = std::max(q.longest2, l2);
      q.shortest2 = std::min(q.shortest2, l2);
    }
  const Row3 a = in.V.row(in.E(e, 0)), b = in.V.row(in.E(e, 1)), c = in.V.row(in.E(e, 2));
  if (in.p == 3) {
    q.measure = (b - a).cross(c - a).norm();
    q.scale = q.longest2;
    q.quality = q.measure / q.scale / (std::sqrt(3.0) / 2.0);
  } else {
    q.det = (b - a).cross(c - a).dot(Row3(in.V.row(in.E(e, 3))) - a);
    q.measure = std::abs(q.det);
    q.scale = q.longest2 * std::sqrt(q.longest2);
    q.quality = q.measure / q.scale * std::sqrt(2.0);
  }
  return q;
}

// Tets with det < 0, among the `oriented` (non-degenerate) ones.
void report_inverted(const Inputs& in, const std::vector<Index>& inverted, Index oriented,
                     std::vector<MeshFinding>* out) {
  FindingBuilder inv(MeshDefect::InvertedTet, CheckSeverity::Warning, "tet", in.o.max_listed);
  for (Index e : inverted) inv.add({e});
  if (inverted.empty()) return;
  const Index e = inverted.front(), count = static_cast<Index>(inverted.size());
  inv.sentence(count == oriented
                   ? fmt::format("every tet is negatively oriented, e.g. tet {}: det[b − a, c − a, d − a] < 0, the "
                                 "opposite of the TetGen and MEDIT convention",
                                 e)
                   : fmt::format("tet {} is inverted: det[b − a, c − a, d − a] < 0 while {} of the {} tets are "
                                 "positive (the mesh folds over itself there)",
                                 e, grouped(oriented - count), grouped(oriented)));
  inv.finish(out);
}

// Degenerate, near-degenerate and inverted elements; edge lengths and worst quality.
void check_elements(const Inputs& in, MeshCheckSummary* s, std::vector<MeshFinding>* out) {
  const char* name = in.element();
  FindingBuilder degenerate(MeshDefect::DegenerateElement, CheckSeverity::Error, name, in.o.max_listed);
  FindingBuilder thin(MeshDefect::NearDegenerateElement, CheckSeverity::Warning, name, in.o.max_listed);
  std::vector<Index> inverted;
  Index oriented = 0;  // non-degenerate tets
  double shortest2 = HUGE_VAL, longest2 = 0.0, worst = HUGE_VAL;
  for (Index e = 0; e < in.m; ++e) {
    bool measurable = true;
    for (int k = 0; k < in.p; ++k) measurable = measurable && in.measurable[in.E(e, k)];
    if (!measurable) continue;  // its vertices are reported already
    if (!in.topological[e]) {
      if (degenerate.add({e}))
        degenerate.sentence(fmt::format("{} {} repeats a corner: it has no {}", name, e, in.p == 3 ? "area" : "volume"));
      continue;
    }
    const ElementShape q = element_shape(in, e);
    shortest2 = std::min(shortest2, q.shortest2);
    longest2 = std::max(longest2, q.longest2);
    if (!(q.measure > in.o.degenerate_tolerance * q.scale)) {
      if (degenerate.add({e}))
        degenerate.sentence(fmt::format("{} {} (vertices {}) is degenerate: {} {:.3g} against its longest edge {:.3g}",
                                        name, e, corners_of(in, e), in.p == 3 ? "area" : "volume",
                                        q.measure / (in.p == 3 ? 2 : 6), std::sqrt(q.longest2)));
      continue;
    }
    worst = std::min(worst, q.quality);
    if (q.quality < in.o.near_degenerate_quality && thin.add({e}))
      thin.sentence(fmt::format("{} {} (vertices {}) is nearly degenerate: quality {:.2g} (1 for a regular {}; "
                                "below {:g} its cotangent weights reach about {:.0g})",
                                name, e, corners_of(in, e), q.quality, name, in.o.near_degenerate_quality,
                                1.0 / q.quality));
    if (in.p == 4) {
      ++oriented;
      if (q.det < 0) inverted.push_back(e);
    }
  }
  if (std::isfinite(shortest2)) {
    s->shortest_edge = std::sqrt(shortest2);
    s->longest_edge = std::sqrt(longest2);
  }
  s->worst_quality = std::isfinite(worst) ? worst : 0.0;
  degenerate.finish(out);
  thin.finish(out);
  report_inverted(in, inverted, oriented, out);
}

// Distance from x to the box [lo, hi] (0 inside).
double distance_to_box(const Row3& x, const Eigen::Vector3d& lo, const Eigen::Vector3d& hi) {
  return (lo.transpose() - x).cwiseMax(x - hi.transpose()).cwiseMax(Row3::Zero()).norm();
}

// Unreferenced vertices: far ones are errors, the others warnings.
void check_unreferenced(const Inputs& in, const MeshCheckSummary& s, std::vector<MeshFinding>* out) {
  FindingBuilder far(MeshDefect::FarUnreferencedVertex, CheckSeverity::Error, "vertex", in.o.max_listed);
  FindingBuilder loose(MeshDefect::UnreferencedVertex, CheckSeverity::Warning, "vertex", in.o.max_listed);
  for (Index v = 0; v < in.n; ++v) {
    if (in.referenced[v] || !in.measurable[v]) continue;
    const double d = distance_to_box(in.V.row(v), s.box_min, s.box_max);
    if (d > in.o.far_distance * s.diagonal) {
      if (far.add({v}))
        far.sentence(s.diagonal > 0.0
                         ? fmt::format("vertex {} is referenced by no element and lies {:.2g} bounding-box diagonals "
                                       "away from the referenced vertices",
                                       v, d / s.diagonal)
                         : fmt::format("vertex {} is referenced by no element and lies {:.3g} away from the referenced "
                                       "vertices, which all coincide",
                                       v, d));
    } else if (loose.add({v})) {
      loose.sentence(fmt::format("vertex {} is referenced by no element: it stays where it is, not deformed", v));
    }
  }
  far.finish(out);
  loose.finish(out);
}

// Vertices within r = duplicate_distance·diagonal of a lower-numbered vertex:
// sort by grid cell and look in the cells the r-ball around each vertex
// reaches. The side 16r (≥ 2r: at most 2 cells per axis) keeps that to one
// cell for most vertices (a ball crosses a face with probability 1/8 per axis).
void check_duplicates(const Inputs& in, const MeshCheckSummary& s, std::vector<MeshFinding>* out) {
  FindingBuilder dup(MeshDefect::DuplicateVertex, CheckSeverity::Warning, "vertex", in.o.max_listed);
  const double r = in.o.duplicate_distance * s.diagonal, side = 16.0 * r;
  using Key = std::array<double, 3>;
  std::vector<std::pair<Key, Index>> cells;
  cells.reserve(static_cast<size_t>(in.n));
  const auto cell_of = [&](const Row3& x) {
    Key k;
    for (int a = 0; a < 3; ++a) k[a] = side > 0.0 ? std::floor((x(a) - s.box_min(a)) / side) : x(a);
    return k;
  };
  for (Index v = 0; v < in.n; ++v)
    if (in.measurable[v]) cells.emplace_back(cell_of(in.V.row(v)), v);
  std::sort(cells.begin(), cells.end());
  for (Index v = 0; v < in.n; ++v) {
    if (!in.measurable[v]) continue;
    const Row3 x = in.V.row(v);
    Index twin = -1;
    const Key lo = cell_of(x - Row3::Constant(r)), hi = cell_of(x + Row3::Constant(r));
    for (int corner = 0; corner < 8; ++corner) {
      Key k;
      bool repeat = false;  // along an axis where the ball stays within one cell, only the low one
      for (int a = 0; a < 3; ++a) {
        const bool up = (corner >> a) & 1;
        k[a] = up ? hi[a] : lo[a];
        repeat = repeat || (up && hi[a] == lo[a]);
      }
      if (repeat) continue;
      auto it = std::lower_bound(cells.begin(), cells.end(), std::make_pair(k, Index(-1)));
      for (; it != cells.end() && it->first == k && it->second < v; ++it)
        if ((Row3(in.V.row(it->second)) - x).norm() <= r && (twin < 0 || it->second < twin)) twin = it->second;
    }
    if (twin >= 0 && dup.add({v}))
      dup.sentence(fmt::format("vertex {} lies at the position of vertex {} (within {:g} bounding-box diagonals): the "
                               "mesh is not connected there, a seam",
                               v, twin, in.o.duplicate_distance));
  }
  dup.finish(out);
}

// Every element side as a sortable key: a triangle edge (a < b) as
// (a·2³² + b, 0, triangle); a tet face (a < b < c) as (a·2³² + b, c, tet).
struct SideKey {
  std::uint64_t ab = 0;
  std::uint32_t c = 0, element = 0;
  bool operator<(const SideKey& o) const { return std::tie(ab, c, element) < std::tie(o.ab, o.c, o.element); }
  bool same_side(const SideKey& o) const { return ab == o.ab && c == o.c; }
};

std::vector<SideKey> sorted_sides(const Inputs& in) {
  std::vector<SideKey> sides;
  sides.reserve(static_cast<size_t>(in.m * in.p));
  for (Index e = 0; e < in.m; ++e) {
    if (!in.topological[e]) continue;
    for (int k = 0; k < in.p; ++k) {
      std::array<std::uint32_t, 3> c{};
      for (int j = 0; j < in.p - 1; ++j) c[j] = static_cast<std::uint32_t>(in.E(e, (k + 1 + j) % in.p));
      std::sort(c.begin(), c.begin() + (in.p - 1));
      const std::uint64_t ab = (std::uint64_t{c[0]} << 32) | c[1];
      sides.push_back(SideKey{ab, in.p == 3 ? 0u : c[2], static_cast<std::uint32_t>(e)});
    }
  }
  std::sort(sides.begin(), sides.end());
  return sides;
}

// The corners of side `key`: (a, b, ·) of an edge, (a, b, c) of a face; the
// first p − 1 count.
std::array<Index, 3> side_corners(const SideKey& key) {
  return {static_cast<Index>(key.ab >> 32), static_cast<Index>(key.ab & 0xffffffffu), static_cast<Index>(key.c)};
}

// Calls run(i, j) for each run [i, j) of the same side.
template <typename Run>
void for_each_side(const std::vector<SideKey>& sides, Run run) {
  for (size_t i = 0; i < sides.size();) {
    size_t j = i;
    while (j < sides.size() && sides[j].same_side(sides[i])) ++j;
    run(i, j);
    i = j;
  }
}

// Edges in more than two triangles, or faces in more than two tets.
void check_manifold_sides(const Inputs& in, const std::vector<SideKey>& sides, std::vector<MeshFinding>* out) {
  const bool tri = in.p == 3;
  FindingBuilder many(tri ? MeshDefect::NonManifoldEdge : MeshDefect::NonManifoldFace, CheckSeverity::Warning,
                      tri ? "edge" : "face", in.o.max_listed);
  for_each_side(sides, [&](size_t i, size_t j) {
    if (j - i <= 2) return;
    const std::array<Index, 3> at = side_corners(sides[i]);
    const std::vector<Index> corners(at.begin(), at.begin() + (in.p - 1));
    if (many.add(corners))
      many.sentence(fmt::format("{} ({}) is shared by {} {}s: the {} is not a manifold there", tri ? "edge" : "face",
                                fmt::join(corners, ", "), j - i, in.element(), tri ? "surface" : "solid"));
  });
  many.finish(out);
}

// Triangles oriented against their neighbours (orientation.h), over the
// edges exactly two triangles share.
void check_orientation(const Inputs& in, const std::vector<SideKey>& sides, std::vector<MeshFinding>* out) {
  std::vector<SharedEdge> shared;
  for_each_side(sides, [&](size_t i, size_t j) {
    if (j - i != 2) return;
    const std::array<Index, 3> at = side_corners(sides[i]);
    shared.push_back({at[0], at[1], static_cast<Index>(sides[i].element), static_cast<Index>(sides[i + 1].element)});
  });
  const OrientationReport r = triangle_orientation(in.E, shared, in.o.max_listed);
  if (r.flipped == 0) return;
  FindingBuilder flipped(MeshDefect::InconsistentOrientation, CheckSeverity::Warning, "triangle", in.o.max_listed);
  for (const Index t : r.first_flipped) flipped.add({t});
  flipped.sentence(fmt::format(
      "triangle {} (vertices {}) is oriented against the rest of its surface (its normal points the other way): "
      "triangles {} and {} both run along edge ({}, {}) from vertex {} to {} ({} of the {} shared edges disagree{})",
      r.first_flipped.front(), corners_of(in, r.first_flipped.front()), r.example, r.partner, r.edge[0], r.edge[1],
      r.edge[0], r.edge[1],
      grouped(r.disagreeing_edges), grouped(static_cast<Index>(shared.size())),
      r.non_orientable ? "; a part of the surface is not orientable" : ""));
  // The count is the triangles to flip (FindingBuilder counted the listed ones).
  flipped.set_count(r.flipped);
  flipped.finish(out);
}

// Union–find with path halving.
Index find_root(std::vector<Index>& parent, Index x) {
  while (parent[x] != x) x = parent[x] = parent[parent[x]];
  return x;
}

void unite(std::vector<Index>& parent, Index x, Index y) {
  const Index rx = find_root(parent, x), ry = find_root(parent, y);
  if (rx != ry) parent[std::max(rx, ry)] = std::min(rx, ry);
}

// Vertices whose elements fall apart into more than one group when elements
// are joined across the sides they share: on a surface, triangles that form
// more than one fan (a "bow-tie"); in a solid, tets that form more than one
// piece (solids touching at the vertex, or only along an edge through it).
// The corners at a vertex are joined when their elements share a side
// containing it (union–find over the p·m corners), then each vertex's
// distinct roots are counted by one sort. `sides`: sorted_sides.
void check_vertex_stars(const Inputs& in, const std::vector<SideKey>& sides, std::vector<MeshFinding>* out) {
  FindingBuilder pinched(MeshDefect::NonManifoldVertex, CheckSeverity::Warning, "vertex", in.o.max_listed);
  const Index corners = in.p * in.m;
  std::vector<Index> parent(static_cast<size_t>(corners));
  std::iota(parent.begin(), parent.end(), 0);
  const auto corner = [&](std::uint32_t e, Index v) {
    int k = 0;
    while (k + 1 < in.p && in.E(e, k) != v) ++k;
    return in.p * static_cast<Index>(e) + k;
  };
  for_each_side(sides, [&](size_t i, size_t j) {
    const std::array<Index, 3> at = side_corners(sides[i]);
    const std::uint32_t first = sides[i].element;
    const auto end = sides.begin() + static_cast<std::ptrdiff_t>(j);
    for (auto it = sides.begin() + static_cast<std::ptrdiff_t>(i + 1); it != end; ++it)
      for (int q = 0; q + 1 < in.p; ++q) unite(parent, corner(it->element, at[q]), corner(first, at[q]));
  });
  std::vector<std::uint64_t> stars;  // vertex·2³² + root of a corner at it
  stars.reserve(static_cast<size_t>(corners));
  for (Index e = 0; e < in.m; ++e)
    if (in.topological[e])
      for (int k = 0; k < in.p; ++k)
        stars.push_back((static_cast<std::uint64_t>(in.E(e, k)) << 32) |
                        static_cast<std::uint64_t>(find_root(parent, in.p * e + k)));
  std::sort(stars.begin(), stars.end());
  stars.erase(std::unique(stars.begin(), stars.end()), stars.end());
  for (size_t i = 0; i < stars.size();) {
    size_t j = i;
    while (j < stars.size() && stars[j] >> 32 == stars[i] >> 32) ++j;
    const Index v = static_cast<Index>(stars[i] >> 32);
    if (j - i > 1 && pinched.add({v}))
      pinched.sentence(in.p == 3 ? fmt::format("vertex {} joins {} separate fans of triangles (a bow-tie): the surface "
                                               "is not a manifold there",
                                               v, j - i)
                                 : fmt::format("vertex {} joins {} separate groups of tets (pieces of solid that meet "
                                               "only at the vertex or along an edge through it, sharing no face): the "
                                               "solid is not a manifold there",
                                               v, j - i));
    i = j;
  }
  pinched.finish(out);
}

void check_components(const Inputs& in, MeshCheckSummary* s, std::vector<MeshFinding>* out) {
  const MeshComponents components = connected_components(in.n, in.E);
  s->components = components.element_components;
  s->anchors_checked = !in.anchored.empty();
  if (s->anchors_checked) {
    MeshFinding f = unanchored_components(components, in.anchored, in.o.max_listed);
    if (f.count > 0) out->push_back(std::move(f));
  }
}

}  // namespace

MeshFinding unanchored_components(const MeshComponents& components, const std::vector<char>& anchored,
                                  Index max_listed) {
  const Index n = static_cast<Index>(components.vertex_component.size());
  if (static_cast<Index>(anchored.size()) != n)
    throw std::invalid_argument(
        fmt::format("unanchored_components: expected {} anchor flags (one per vertex), got {}", n, anchored.size()));
  const size_t count = static_cast<size_t>(components.element_components);
  std::vector<char> held(count, 0);
  std::vector<Index> size(count, 0), first(count, -1);
  for (Index v = 0; v < n; ++v) {
    const int c = components.vertex_component[static_cast<size_t>(v)];
    if (c >= components.element_components) continue;  // unreferenced: kept, not deformed
    held[c] |= anchored[static_cast<size_t>(v)] ? 1 : 0;
    if (first[c] < 0) first[c] = v;
    ++size[c];
  }
  FindingBuilder loose(MeshDefect::UnanchoredComponent, CheckSeverity::Error, "component", max_listed);
  for (size_t c = 0; c < count; ++c)
    if (!held[c] && loose.add({static_cast<Index>(c)}))
      loose.sentence(fmt::format("connected component {} ({} vertices, first vertex {}) has no handle or fixed region "
                                 "anchoring it: nothing holds it in place, so its pose is not determined",
                                 c, grouped(size[c]), first[c]));
  std::vector<MeshFinding> out;
  loose.finish(&out);
  return out.empty() ? MeshFinding{MeshDefect::UnanchoredComponent, CheckSeverity::Error, 0, "component", {}, ""}
                     : out.front();
}

MeshCheckSummary diagnose_mesh(const VerticesRef& V, const ElementsRef& E, const std::vector<char>& anchored,
                               const MeshCheckOptions& options) {
  const Timer timer;
  std::string why;
  if (!options.is_valid(&why)) throw std::invalid_argument("diagnose_mesh: " + why);
  if (V.cols() != 3) throw std::invalid_argument(fmt::format("diagnose_mesh: V: expected 3 columns, got {}", V.cols()));
  if (E.cols() != 3 && E.cols() != 4)
    throw std::invalid_argument(fmt::format("diagnose_mesh: E: expected 3 or 4 columns, got {}", E.cols()));
  if (!anchored.empty() && static_cast<Index>(anchored.size()) != V.rows())
    throw std::invalid_argument(
        fmt::format("diagnose_mesh: anchored: expected {} flags (one per vertex), got {}", V.rows(), anchored.size()));

  MeshCheckSummary s;
  Inputs in(V, E, anchored, options);
  s.vertices = in.n;
  s.elements = in.m;
  s.corners = in.p;
  std::vector<MeshFinding>& out = s.findings;
  const auto alone = [&](MeshDefect defect, const std::string& message) {
    out.push_back(MeshFinding{defect, CheckSeverity::Error, 1, "", {}, message});
  };
  if (in.n == 0) alone(MeshDefect::NoVertices, "the mesh has no vertices");
  if (in.n > 0) check_coordinates(in, &out);
  if (in.m == 0) alone(MeshDefect::NoElements, fmt::format("the mesh has no {}s, only {} vertices", in.element(),
                                                           grouped(in.n)));
  if (in.n > 0 && in.m > 0 && check_indices(in, &out)) {
    scan_references(in, &s);
    check_elements(in, &s, &out);
    check_unreferenced(in, s, &out);
    check_duplicates(in, s, &out);
    const std::vector<SideKey> sides = sorted_sides(in);
    check_manifold_sides(in, sides, &out);
    if (in.p == 3) check_orientation(in, sides, &out);
    check_vertex_stars(in, sides, &out);
    check_components(in, &s, &out);
  }
  std::stable_sort(out.begin(), out.end(), [](const MeshFinding& a, const MeshFinding& b) {
    return std::make_pair(a.severity != CheckSeverity::Error, a.defect) <
           std::make_pair(b.severity != CheckSeverity::Error, b.defect);
  });
  s.verdict = s.has_errors() ? MeshCheckStatus::Errors
              : s.has_warnings() ? MeshCheckStatus::Warnings
                                 : MeshCheckStatus::Clean;
  s.status = Status::Success;
  if (!s.findings.empty()) s.message = s.findings.front().message;
  s.seconds = timer.seconds();
  return s;
}

void MeshCheckSummary::add_details(Report* out) const {
  const auto list = [](const Eigen::Vector3d& x) { return std::vector<double>{x(0), x(1), x(2)}; };
  Index errors = 0;
  for (const MeshFinding& f : findings) errors += f.severity == CheckSeverity::Error ? 1 : 0;
  out->add("verdict", verdict)
      .add("vertices", vertices)
      .add("elements", elements)
      .add("corners", corners)
      .add("box_min", list(box_min))
      .add("box_max", list(box_max))
      .add("diagonal", diagonal)
      .add("shortest_edge", shortest_edge)
      .add("longest_edge", longest_edge)
      .add("worst_quality", worst_quality)
      .add("components", components)
      .add("anchors_checked", anchors_checked)
      .add("errors", errors)
      .add("warnings", static_cast<Index>(findings.size()) - errors)
      .add("seconds", seconds);
}

}  // namespace qpreduce::deform
