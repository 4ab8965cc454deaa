// The deformer's model set-up (state.h): the compacted proxy mesh, the
// topology and control layer, the rotational clusters with the Rigid patches'
// own, the control matrix P, the float basis P·[N UD], and the hand-over to
// the on-site step (State::finish).
#include "state.h"

#include "deformer/control_layer.h"
#include "deformer/handle_checks.h"

#include <qpreduce/checks.h>

#include <fmt/format.h>

#include <algorithm>
#include <utility>

namespace qpreduce::deform {
namespace detail {

CompactMesh compact_mesh(const Vertices& V, const ElementsRef& E,
                                          const std::vector<Index>& unreferenced) {
  CompactMesh cm;
  const Index n = V.rows();
  std::vector<Index> new_of_old(static_cast<size_t>(n), -1);
  size_t next_unref = 0;
  for (Index v = 0; v < n; ++v) {
    if (next_unref < unreferenced.size() && unreferenced[next_unref] == v) {
      ++next_unref;
      continue;
    }
    new_of_old[static_cast<size_t>(v)] = static_cast<Index>(cm.old_of_new.size());
    cm.old_of_new.push_back(v);
  }
  cm.V.resize(static_cast<Index>(cm.old_of_new.size()), 3);
  for (size_t i = 0; i < cm.old_of_new.size(); ++i) cm.V.row(static_cast<Index>(i)) = V.row(cm.old_of_new[i]);
  cm.E.resize(E.rows(), E.cols());
  for (Index e = 0; e < E.rows(); ++e)
    for (Index c = 0; c < E.cols(); ++c) cm.E(e, c) = static_cast<int>(new_of_old[static_cast<size_t>(E(e, c))]);
  return cm;
}

void Model::set_topology(const DeformableMesh& mesh) {
  check_mesh_elements(mesh, "DeformableMesh");
  check_patch_labels(mesh, "DeformableMesh");
  const bool tet = mesh.is_tet();
  rest = mesh.V;
  n = mesh.V.rows();
  patch_of_vertex = mesh.patch_of_vertex;
  patch_types = mesh.patch_types;
  // Vertices used by no element carry no energy: an internal Fixed patch
  // holds those that are not in a patch already at their rest positions.
  const ElementsRef E = tet ? ElementsRef(mesh.T) : ElementsRef(mesh.F);
  components = connected_components(n, E);
  unreferenced = components.unreferenced;
  std::vector<Index> loose;
  for (Index v : unreferenced)
    if (patch_of_vertex.empty() || patch_of_vertex[v] < 0) loose.push_back(v);
  if (!loose.empty()) {
    if (patch_of_vertex.empty()) patch_of_vertex.assign(static_cast<size_t>(n), -1);
    for (Index v : loose) patch_of_vertex[v] = static_cast<int>(patch_types.size());
    patch_types.push_back(PatchType::Fixed);
  }
  s = static_cast<Index>(patch_types.size());
  std::vector<Index> patch_size(static_cast<size_t>(s), 0);
  for (int p : patch_of_vertex)
    if (p >= 0) ++patch_size[static_cast<size_t>(p)];
  fixed_patches.clear();
  for (Index p = 0; p < s; ++p) {
    if (patch_size[p] == 0) throw std::invalid_argument(fmt::format("DeformableMesh: patch {} has no vertex", p));
    if (patch_types[p] == PatchType::Fixed) fixed_patches.push_back(p);
  }
  control_of_free.assign(static_cast<size_t>(n), -1);
  Index free_count = 0;
  for (Index v = 0; v < n; ++v)
    if (patch_of_vertex.empty() || patch_of_vertex[v] < 0) control_of_free[v] = 3 * free_count++;
  patch_base = 3 * free_count;
  nu = patch_base + 12 * s;
  keep_q = false;
  elements = tet ? tet_elements(mesh.V, mesh.T) : spokes_and_rims_elements(mesh.V, mesh.F);
}

void Model::keep_rotation_corrections() {
  if (keep_q) return;
  keep_q = true;
  nu += 4 * elements.size();
}

void Model::set_clusters(std::vector<int> labels, Index count) {
  const Index r = elements.size();
  check_size("rotational cluster labels", r, static_cast<Index>(labels.size()));
  std::vector<Index> size(static_cast<size_t>(count), 0);
  for (Index k = 0; k < r; ++k) {
    if (labels[k] < 0 || labels[k] >= count) {
      throw std::invalid_argument(fmt::format("rotational clusters: element {} has label {} outside [0, {})", k,
                                              labels[k], count));
    }
    ++size[static_cast<size_t>(labels[k])];
  }
  for (Index c = 0; c < count; ++c)
    if (size[c] == 0) throw std::invalid_argument(fmt::format("rotational clusters: cluster {} is empty", c));
  clusters = std::move(labels);
  d = count;
  cluster_measure = Eigen::VectorXd::Zero(d);
  for (Index k = 0; k < r; ++k) cluster_measure(clusters[k]) += elements.measure(k);
}

std::vector<Index> Model::patch_elements(Index p, const Tetrahedra& T) const {
  std::vector<Index> out;
  if (T.rows() == 0) {
    for (Index v = 0; v < n; ++v)
      if (patch_of_vertex[v] == p) out.push_back(v);
    return out;
  }
  for (int need = 4; need >= 1 && out.empty(); need -= 3) {  // all four corners, else any
    for (Index t = 0; t < T.rows(); ++t) {
      int inside = 0;
      for (int c = 0; c < 4; ++c) inside += patch_of_vertex[T(t, c)] == p;
      if (inside >= need) out.push_back(t);
    }
  }
  return out;
}

void Model::separate_rigid_clusters(const Tetrahedra& T) {
  rigid_cluster_of_patch.assign(static_cast<size_t>(s), -1);
  std::vector<int> labels = clusters;
  std::vector<char> taken(labels.size(), 0);
  int next = static_cast<int>(d);
  std::vector<Index> rigid;
  for (Index p = 0; p < s; ++p) {
    if (patch_types[p] != PatchType::Rigid) continue;
    rigid.push_back(p);
    for (Index k : patch_elements(p, T)) {
      if (taken[k]) continue;  // a tet touching two rigid patches stays with the first
      taken[k] = 1;
      labels[k] = next;
    }
    ++next;
  }
  if (rigid.empty()) return;
  // Drop emptied clusters, keeping the order.
  std::vector<int> remap(static_cast<size_t>(next), -1);
  for (int l : labels) remap[l] = 0;
  int count = 0;
  for (int& r : remap)
    if (r == 0) r = count++;
  for (int& l : labels) l = remap[l];
  for (size_t i = 0; i < rigid.size(); ++i) {
    const int c = remap[d + static_cast<Index>(i)];
    if (c < 0) throw std::invalid_argument(fmt::format("Rigid patch {} has no element", rigid[i]));
    rigid_cluster_of_patch[rigid[i]] = c;
  }
  set_clusters(std::move(labels), count);
}

void Model::find_rigid_clusters(const Tetrahedra& T) {
  rigid_cluster_of_patch.assign(static_cast<size_t>(s), -1);
  for (Index p = 0; p < s; ++p) {
    if (patch_types[p] != PatchType::Rigid) continue;
    const std::vector<Index> el = patch_elements(p, T);
    if (el.empty()) throw std::invalid_argument(fmt::format("Rigid patch {} has no element", p));
    const int c = clusters[el.front()];
    for (Index k : el)
      if (clusters[k] != c) throw std::invalid_argument(fmt::format("Rigid patch {} spans several clusters", p));
    rigid_cluster_of_patch[p] = c;
  }
}

void Model::control_row(Index v, int a, double scale, Index col, Triplets* t) const {
  add_control_row(patch_of_vertex, rest, control_of_free, patch_base, v, a, scale, col, t);
}

SparseMatrix<double> Model::control_matrix() const {
  Triplets tp, row;
  tp.reserve(static_cast<size_t>(3 * n) * 4);
  for (Index v = 0; v < n; ++v)
    for (int a = 0; a < 3; ++a) {
      row.clear();
      control_row(v, a, 1.0, 0, &row);
      for (const auto& e : row) tp.emplace_back(3 * v + a, e.row(), e.value());
    }
  SparseMatrix<double> P(3 * n, nu);
  P.setFromTriplets(tp.begin(), tp.end());
  return P;
}

std::pair<Index, Index> Model::vertex_rows_of(Index first_row, Index rows) const {
  // Row 3v + a goes with its control unknown (free v) or with the last free
  // row before it (a patch vertex; the first block when there is none).
  // control_of_free ascends with v, so these rows are contiguous.
  const auto mine = [&](Index key) { return key < 0 ? first_row == 0 : key >= first_row && key < first_row + rows; };
  Index first = -1, last = -1, key = -1;
  for (Index v = 0; v < n; ++v)
    for (int a = 0; a < 3; ++a) {
      if (control_of_free[v] >= 0) key = control_of_free[v] + a;
      if (mine(key)) {
        if (first < 0) first = 3 * v + a;
        last = 3 * v + a;
      }
    }
  return first < 0 ? std::pair<Index, Index>{0, 0} : std::pair<Index, Index>{first, last - first + 1};
}

template <typename Rows>
void Model::basis_rows_from(Index first_row, const Matrix<double>& N_rows, const Matrix<double>& UD_rows,
                            Index first, Index count, Rows* out) const {
  const Index rows = N_rows.rows(), p = nx + 9 * d;
  check_size("Model::basis_rows_from: UD rows", rows, UD_rows.rows());
  check_size("Model::basis_rows_from: patch rows", 12 * s, patch_rows.rows());
  // P's rows [first, first + count) split by its columns: PB on the control
  // rows of [N UD] they use (lo ≤ c − first_row < hi), PP on the patch
  // unknowns' rows (patch_rows).
  Triplets tb, tp, row;
  Index lo = rows, hi = 0;
  for (Index i = first; i < first + count; ++i) {
    row.clear();
    control_row(i / 3, static_cast<int>(i % 3), 1.0, 0, &row);
    for (const auto& e : row) {
      const Index c = e.row();
      if (c >= patch_base) {
        tp.emplace_back(i - first, c - patch_base, e.value());
      } else if (c >= first_row && c < first_row + rows) {
        tb.emplace_back(i - first, c - first_row, e.value());
        lo = std::min(lo, c - first_row);
        hi = std::max(hi, c - first_row + 1);
      } else {
        throw std::logic_error(fmt::format("Model::basis_rows_from: vertex row {} needs control row {} outside [{}, {})",
                                           i, c, first_row, first_row + rows));
      }
    }
  }
  lo = std::min(lo, hi);
  for (auto& t : tb) t = Eigen::Triplet<double>(t.row(), t.col() - lo, t.value());
  SparseMatrix<double> PB(count, hi - lo), PP(count, 12 * s);
  PB.setFromTriplets(tb.begin(), tb.end());
  PP.setFromTriplets(tp.begin(), tp.end());
  out->resize(count, p);
  constexpr Index kBlock = 32;  // columns per double temporary ((hi − lo) × 32)
  Matrix<double> block, product;
  for (Index j = 0; j < p; j += kBlock) {
    const Index w = std::min(kBlock, p - j);
    block.resize(hi - lo, w);
    for (Index c = 0; c < w; ++c)
      block.col(c) = j + c < nx ? N_rows.col(j + c).segment(lo, hi - lo) : UD_rows.col(j + c - nx).segment(lo, hi - lo);
    product = PB * block;
    if (s > 0) product += PP * patch_rows.middleCols(j, w);
    out->middleCols(j, w) = product.cast<typename Rows::Scalar>();
  }
}

template void Model::basis_rows_from<RowMatrixF>(Index, const Matrix<double>&, const Matrix<double>&, Index, Index,
                                                 RowMatrixF*) const;

void Model::make_basis(Index first_row, const Matrix<double>& N_rows, const Matrix<double>& UD_rows) {
  check_size("Model::make_basis: UD rows", N_rows.rows(), UD_rows.rows());
  const auto [first, count] = vertex_rows_of(first_row, N_rows.rows());
  basis_first = first;
  if (double_basis) {
    basis_rows_from(first_row, N_rows, UD_rows, first, count, &basis_double);
  } else {
    basis_rows_from(first_row, N_rows, UD_rows, first, count, &basis);
  }
}

void Model::take_patch_rows() {
  const Matrix<double>& N = solver.subspace().N;
  const Matrix<double>& U = solver.subspace().UD;
  patch_rows.resize(12 * s, nx + 9 * d);
  for (Index i = 0; i < 12 * s; ++i) patch_rows.row(i) << N.row(patch_base + i), U.row(patch_base + i);
}

void Model::finish_reduction() {
  std::vector<char> rigid(static_cast<size_t>(d), 0);
  for (Index c : rigid_cluster_of_patch)
    if (c >= 0) rigid[static_cast<size_t>(c)] = 1;
  projection = energy_model->projection(cluster_geometry(rest, elements, clusters, d, std::move(rigid)));
  free_vertices.assign(static_cast<size_t>(patch_base / 3), -1);
  for (Index v = 0; v < n; ++v)
    if (control_of_free[v] >= 0) free_vertices[static_cast<size_t>(control_of_free[v] / 3)] = v;
}

void describe(const Model& model, PrecomputeSummary* summary) {
  summary->vertices = model.n;
  summary->elements = model.elements.size();
  summary->rotational_proxies = model.d;
  summary->linear_proxies = model.m;
  summary->patches = model.s;
  summary->reduced_size = model.nx + 9 * model.d;
}

}  // namespace detail

void Deformer::State::finish(const DeformerOptions& options) {
  model.finish_reduction();
  model.given_elements = in_given_units(model.elements, model.frame);
  model.energy_unit = energy_unit(model.frame, !model.elements.is_surface);
  const Index d = model.d, nx = model.nx;
  pose.S.resize(9 * d);
  pose.x = Eigen::VectorXd::Zero(nx);
  pose.wf.resize(nx + 9 * d);
  if (model.double_basis) pose.wd.resize(nx + 9 * d);
  work.s_local.resize(9 * d);
  settings.alternating.iterations = options.iterations;
  settings.alternating.tolerance = options.tolerance;
  settings.alternating.time_budget = options.time_budget;
  settings.alternating.anderson_window = options.anderson_window;
  settings.alternating.second_order = options.second_order;
  settings.cold_start_rounds = options.cold_start_rounds;
  settings.cold_start_tolerance = options.cold_start_tolerance;
  settings.soften_unreachable_handles = options.soften_unreachable_handles;
  settings.alternating.float_products = options.float_rounds;
  settings.alternating.threads = options.round_threads;
  settings.global_rotation = options.global_rotation;
  // Phase 1's and the fused rounds' per-solver parts (H_zz's lifted inverse,
  // its responses P0, C0 = M_N·P0) belong to the precompute: the first handle
  // set then costs what the later ones do (unless prepare_onsite is false).
  onsite.alternation.prepare(model.solver, model.MN, model.MU, *model.projection, fused_precision(),
                             options.prepare_onsite);
  ready = true;
}

}  // namespace qpreduce::deform
