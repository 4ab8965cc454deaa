#include "qpreduce/deform/deformer/deformer.h"

#include "state.h"
#include "sparse_products.h"
#include "qpreduce/deform/mesh/geometry.h"

#include <qpreduce/point_reconstruction.h>
#include <qpreduce/support.h>

#include <Eigen/LU>

#include <fmt/format.h>

#include <algorithm>
#include <optional>
#include <utility>
#include <cmath>

namespace qpreduce::deform {

using detail_deformer::compact_mesh;
using detail_deformer::CompactMesh;
using detail_deformer::Triplets;


bool DeformerOptions::is_valid(std::string* why) const {
  auto fail = [why](std::string msg) {
    if (why) *why = std::move(msg);
    return false;
  };
  std::string sub;
  if (!energy.is_valid(&sub)) return fail("energy: " + sub);
  if (rotational_proxies < 1) return fail(fmt::format("rotational_proxies must be ≥ 1, got {}", rotational_proxies));
  if (linear_proxies < 0) return fail(fmt::format("linear_proxies must be ≥ 0, got {}", linear_proxies));
  if (iterations < 1) return fail(fmt::format("iterations must be ≥ 1, got {}", iterations));
  if (round_threads < 0) return fail(fmt::format("round_threads must be ≥ 0 (0: all), got {}", round_threads));
  if (!clustering.is_valid(&sub)) return fail("clustering: " + sub);
  if (!subspace.is_valid(&sub)) return fail("subspace: " + sub);
  if (!custom_model && model == ModelKind::Conformal && (!(conformal_bound > 1.0) || !std::isfinite(conformal_bound))) {
    return fail(fmt::format("conformal_bound must be finite and > 1, got {}", conformal_bound));
  }
  return true;
}

std::shared_ptr<const DeformationModel> DeformerOptions::resolve_model() const {
  if (custom_model) return custom_model;
  return model == ModelKind::Conformal ? make_conformal_model(energy, conformal_bound) : make_arap_model(energy);
}

CompactMesh detail_deformer::compact_mesh(const Vertices& V, const ElementsRef& E,
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

void Deformer::State::set_topology(const DeformableMesh& model) {
  const bool tet = model.is_tet();
  if (tet == (model.F.rows() > 0)) {
    throw std::invalid_argument("DeformableMesh: give exactly one of F (surface) and T (tetrahedra)");
  }
  if (tet) {
    check_mesh("DeformableMesh", TetMesh{model.V, model.T, {}});
  } else {
    check_mesh("DeformableMesh", TriangleMesh{model.V, model.F});
  }
  rest = model.V;
  n = model.V.rows();
  patch_of_vertex = model.patch_of_vertex;
  patch_types = model.patch_types;
  if (!patch_of_vertex.empty()) {
    check_size("DeformableMesh::patch_of_vertex size", n, static_cast<Index>(patch_of_vertex.size()));
    for (Index v = 0; v < n; ++v) {
      const int p = patch_of_vertex[v];
      if (p < -1 || p >= static_cast<int>(patch_types.size())) {
        throw std::invalid_argument(fmt::format("DeformableMesh::patch_of_vertex: vertex {} has patch {} outside "
                                                "[-1, {})",
                                                v, p, patch_types.size()));
      }
    }
  }
  // Vertices used by no element carry no energy: an internal Fixed patch
  // holds those that are not in a patch already at their rest positions.
  const ElementsRef E = tet ? ElementsRef(model.T) : ElementsRef(model.F);
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
  elements = tet ? tet_elements(model.V, model.T) : spokes_and_rims_elements(model.V, model.F);
}

void Deformer::State::keep_rotation_corrections() {
  if (keep_q) return;
  keep_q = true;
  nu += 4 * elements.size();
}

void Deformer::State::set_clusters(std::vector<int> labels, Index count) {
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

std::vector<Index> Deformer::State::patch_elements(Index p, const Tetrahedra& T) const {
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

void Deformer::State::separate_rigid_clusters(const Tetrahedra& T) {
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

void Deformer::State::find_rigid_clusters(const Tetrahedra& T) {
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

void Deformer::State::control_row(Index v, int a, double scale, Index col, Triplets* t) const {
  const int p = patch_of_vertex.empty() ? -1 : patch_of_vertex[v];
  if (p < 0) {
    t->emplace_back(control_of_free[v] + a, col, scale);
    return;
  }
  const Index base = patch_base + 12 * p;
  for (int c = 0; c < 3; ++c) t->emplace_back(base + 3 * a + c, col, scale * rest(v, c));
  t->emplace_back(base + 9 + a, col, scale);
}

SparseMatrix<double> Deformer::State::control_matrix() const {
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

void Deformer::State::make_basis(const SparseMatrix<double>& P) {
  const Matrix<double>& N = solver.subspace().N;
  const Matrix<double>& U = solver.subspace().UD;
  basis.resize(3 * n, nx + 9 * d);
  constexpr Index kBlock = 32;  // columns per double temporary (3n × 32)
  for (Index j = 0; j < nx + 9 * d; j += kBlock) {
    const Index w = std::min(kBlock, nx + 9 * d - j);
    Matrix<double> block(nu, w);
    for (Index c = 0; c < w; ++c) block.col(c) = j + c < nx ? N.col(j + c) : U.col(j + c - nx);
    basis.middleCols(j, w) = (P * block).cast<float>();
  }
}

void Deformer::State::finish(const DeformerOptions& options) {
  std::vector<char> rigid(static_cast<size_t>(d), 0);
  for (Index c : rigid_cluster_of_patch)
    if (c >= 0) rigid[static_cast<size_t>(c)] = 1;
  projection = model->projection(cluster_geometry(rest, elements, clusters, d, std::move(rigid)));
  const Matrix<double>& N = solver.subspace().N;
  const Matrix<double>& U = solver.subspace().UD;
  patch_rows.resize(12 * s, nx + 9 * d);
  for (Index i = 0; i < 12 * s; ++i) patch_rows.row(i) << N.row(patch_base + i), U.row(patch_base + i);
  free_vertices.assign(static_cast<size_t>(patch_base / 3), -1);
  for (Index v = 0; v < n; ++v)
    if (control_of_free[v] >= 0) free_vertices[static_cast<size_t>(control_of_free[v] / 3)] = v;
  S.resize(9 * d);
  x = Eigen::VectorXd::Zero(nx);
  s_local.resize(9 * d);
  w.resize(nx + 9 * d);
  wf.resize(nx + 9 * d);
  vf.resize(3 * n);
  alternating.iterations = options.iterations;
  alternating.float_products = options.float_rounds;
  alternating.threads = options.round_threads;
  global_rotation = options.global_rotation;
  // Phase 1's and the fused rounds' per-solver parts (H_zz's lifted inverse,
  // its responses P0, C0 = M_N·P0) belong to the precompute: the first handle
  // set then costs what the later ones do.
  phase1.prepare(solver);
  fused.prepare(phase1, MN, MU, fused_precision());
  fused_inputs_plain = true;
  ready = true;
}

Deformer::Deformer() : state_(std::make_unique<State>()) {}
Deformer::~Deformer() = default;
Deformer::Deformer(Deformer&&) noexcept = default;
Deformer& Deformer::operator=(Deformer&&) noexcept = default;

bool Deformer::ready() const { return state_->ready; }
Index Deformer::vertex_count() const { return state_->n; }
Index Deformer::rotational_proxies() const { return state_->d; }
Index Deformer::linear_proxies() const { return state_->m; }
Index Deformer::patch_count() const { return state_->s; }
Index Deformer::handle_rows() const { return state_->rows; }
const std::vector<int>& Deformer::clusters() const { return state_->clusters; }
const std::vector<int>& Deformer::patch_of_vertex() const { return state_->patch_of_vertex; }
const RotationElements& Deformer::elements() const { return state_->elements; }
const Eigen::VectorXd& Deformer::rotations() const { return state_->S; }
Eigen::VectorXd Deformer::cluster_scales() const {
  Eigen::VectorXd psi(state_->d);
  for (Index a = 0; a < state_->d; ++a) psi(a) = std::cbrt(Eigen::Map<const Eigen::Matrix3d>(state_->S.data() + 9 * a).determinant());
  return psi;
}
const std::shared_ptr<const DeformationModel>& Deformer::model() const { return state_->model; }
Eigen::Matrix<double, 3, 4> Deformer::patch_transform(Index p) const {
  const State& S = *state_;
  if (p < 0 || p >= S.s) throw std::invalid_argument(fmt::format("patch_transform: patch {} outside [0, {})", p, S.s));
  const Index base = 3 * S.m + 12 * p;
  Eigen::Matrix<double, 3, 4> T;
  for (int a = 0; a < 3; ++a) {
    for (int c = 0; c < 3; ++c) T(a, c) = S.x(base + 3 * a + c);
    T(a, 3) = S.x(base + 9 + a);
  }
  return S.r0 * T;
}
const Eigen::Matrix3d& Deformer::global_rotation() const { return state_->r0; }
const Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>& Deformer::reconstruction_basis() const {
  return state_->basis;
}
const Eigen::VectorXf& Deformer::reduced_coordinates() const { return state_->wf; }

PrecomputeSummary Deformer::precompute(const DeformableMesh& model, const DeformerOptions& options,
                                       const ProgressFn& progress) {
  std::string why;
  if (!options.is_valid(&why)) throw std::invalid_argument("DeformerOptions: " + why);
  const bool tet = model.is_tet();
  auto report = [&](const char* stage, double f) {
    if (progress) progress(stage, f);
  };
  const Timer total;
  auto st = std::make_unique<State>();
  State& S = *st;
  PrecomputeSummary summary;
  S.set_topology(model);
  S.inputs = {model.F, model.T, model.clusters, model.linear.groups, options};
  S.model = options.resolve_model();
  const Index n = S.n;
  const ElementsRef E = tet ? ElementsRef(model.T) : ElementsRef(model.F);

  // The automatic proxies are placed on the referenced part of the mesh: a
  // compacted copy only when some vertex is unreferenced, made once.
  std::optional<CompactMesh> compact;
  if (!S.unreferenced.empty() && (model.clusters.empty() || model.linear.count() == 0)) {
    compact = compact_mesh(model.V, E, S.unreferenced);
  }
  const VerticesRef PV = compact ? VerticesRef(compact->V) : VerticesRef(model.V);
  const ElementsRef PE = compact ? ElementsRef(compact->E) : E;

  // Rotation clusters.
  report("clusters", 0.0);
  Timer t;
  const Index r = S.elements.size();
  if (!model.clusters.empty()) {
    check_size("DeformableMesh::clusters size", r, static_cast<Index>(model.clusters.size()));
    for (Index k = 0; k < r; ++k) {
      if (model.clusters[k] < 0) {
        throw std::invalid_argument(fmt::format("DeformableMesh::clusters: element {} has negative label {}", k,
                                                model.clusters[k]));
      }
    }
    S.set_clusters(model.clusters, 1 + *std::max_element(model.clusters.begin(), model.clusters.end()));
  } else {
    // Clusters of the referenced part (surfaces: one label per vertex; an
    // unreferenced vertex is an element without edges, labelled 0).
    Clustering clustering;
    const ClusterSummary cs = compute_rotation_clusters(PV, PE, tet ? ClusterElement::Element : ClusterElement::Vertex,
                                                options.rotational_proxies, options.clustering, &clustering);
    if (!cs.ok()) {
      summary.status = cs.status;
      summary.message = "rotational clusters: " + cs.message;
      return summary;
    }
    std::vector<int> labels = std::move(clustering.labels);
    if (!tet && compact) {
      std::vector<int> full(static_cast<size_t>(n), 0);
      for (size_t i = 0; i < compact->old_of_new.size(); ++i)
        full[static_cast<size_t>(compact->old_of_new[i])] = labels[i];
      labels = std::move(full);
    }
    S.set_clusters(std::move(labels), clustering.count);
  }
  S.separate_rigid_clusters(model.T);
  summary.clustering_seconds = t.seconds();

  // Linear proxies, restricted to free vertices.
  report("linear proxies", 0.1);
  LinearProxies proxies = model.linear;
  if (proxies.count() == 0) {
    // Farthest-point samples of the referenced part, in original indices.
    proxies = linear_proxies_fps(PV, PE, options.linear_proxies);
    if (compact)
      for (auto& g : proxies.groups)
        for (Index& v : g) v = compact->old_of_new[static_cast<size_t>(v)];
  }
  std::vector<std::vector<Index>> groups;
  for (const auto& g : proxies.groups) {
    std::vector<Index> kept;
    for (Index v : g) {
      if (v < 0 || v >= n) throw std::invalid_argument(fmt::format("linear proxies: vertex {} outside [0, {})", v, n));
      if (S.control_of_free[v] >= 0) kept.push_back(v);
    }
    if (!kept.empty()) groups.push_back(std::move(kept));
  }
  S.m = static_cast<Index>(groups.size());
  S.nx = 3 * S.m + 12 * S.s;
  // Every component needs a proxy or a patch.
  {
    const MeshComponents& comps = S.components;
    std::vector<char> pinned(static_cast<size_t>(comps.count), 0);
    for (const auto& g : groups)
      for (Index v : g) pinned[static_cast<size_t>(comps.vertex_component[v])] = 1;
    for (Index v = 0; v < n; ++v)
      if (S.control_of_free[v] < 0) pinned[static_cast<size_t>(comps.vertex_component[v])] = 1;
    for (Index c = 0; c < comps.count; ++c) {
      if (!pinned[c]) {
        throw std::invalid_argument(fmt::format(
            "DeformableMesh: connected component {} of {} has no linear proxy and no patch; the KKT system (Eq. 14) "
            "would be singular (use at least {} linear proxies, or patch that component)",
            c, comps.count, comps.count));
      }
    }
  }

  // The model's energy (Q eliminated when L_QQ is block diagonal), then the
  // control layer.
  report("energy", 0.15);
  t.reset();
  ModifiedArapSystem full = S.model->assemble(model.V, S.elements, S.clusters, S.d);
  check_size("DeformationModel::assemble: L rows", 3 * n + 4 * r, full.L.rows());
  check_size("DeformationModel::assemble: D columns", 9 * S.d, full.D.cols());
  SparseMatrix<double> Hu, Du, DV;
  SparseMatrix<double> P;
  if (full.q_separable) {
    EliminatedArapSystem elim = eliminate_rotation_corrections(full);
    P = S.control_matrix();
    if (detail_deformer::is_identity(P)) {  // every vertex free, no patch: u = V′
      Hu = std::move(elim.H);
      Du = std::move(elim.Ds);
    } else {
      const SparseMatrix<double> Pt = P.transpose();
      Hu = detail_deformer::parallel_product(Pt, detail_deformer::parallel_product(elim.H, P));
      Du = detail_deformer::parallel_product(Pt, elim.Ds);
    }
    DV = std::move(elim.DV);
  } else {
    // Q stays: u = [control (n_u − 4r); Q], [V′; Q] = blockdiag(P_V, I)·u.
    S.keep_rotation_corrections();
    P = S.control_matrix();
    SparseMatrix<double> Pfull(3 * n + 4 * r, S.nu);
    {
      Triplets tp;
      tp.reserve(static_cast<size_t>(P.nonZeros() + 4 * r));
      for (Index c = 0; c < P.outerSize(); ++c)
        for (SparseMatrix<double>::InnerIterator it(P, c); it; ++it) tp.emplace_back(it.row(), c, it.value());
      const Index q0 = S.patch_base + 12 * S.s;
      for (Index i = 0; i < 4 * r; ++i) tp.emplace_back(3 * n + i, q0 + i, 1.0);
      Pfull.setFromTriplets(tp.begin(), tp.end());
    }
    const SparseMatrix<double> Pt = Pfull.transpose();
    Hu = Pt * full.L * Pfull;
    Hu = 0.5 * (Hu + SparseMatrix<double>(Hu.transpose()));
    Du = Pt * full.D;
    DV = full.D.topRows(3 * n);
  }
  full = ModifiedArapSystem();  // free L, D before the factorization
  Triplets tc;
  for (Index j = 0; j < S.m; ++j) {
    const double w = 1.0 / static_cast<double>(groups[j].size());
    for (Index v : groups[j])
      for (int a = 0; a < 3; ++a) tc.emplace_back(S.control_of_free[v] + a, 3 * j + a, w);
  }
  for (Index p = 0; p < S.s; ++p)
    for (int c = 0; c < 12; ++c) tc.emplace_back(S.patch_base + 12 * p + c, 3 * S.m + 12 * p + c, 1.0);
  SparseMatrix<double> C(S.nu, S.nx);
  C.setFromTriplets(tc.begin(), tc.end());
  summary.assembly_seconds = t.seconds();

  // Augment with the cheapest columns: every patch column (one entry each)
  // and, when groups are long, only the shortest group's three columns.
  SubspaceOptions sub = options.subspace;
  // Phase 1 holds the rotational coordinates fixed (y = S), so U·D need not
  // have full rank: rotations whose effect the linear proxies or patches
  // already pin (all of them, with a proxy at every vertex) are legitimate.
  sub.check_dependent_cd = false;
  if (sub.augment_columns.empty()) {
    double fill = 0.0;
    for (const auto& g : groups) fill += 3.0 * static_cast<double>(g.size() * g.size());
    if (fill > sub.max_augmentation_fill * static_cast<double>(Hu.nonZeros()) && S.m > 0) {
      // One group per component suffices; the shortest ones of each component.
      const MeshComponents& comps = S.components;
      std::vector<Index> best(static_cast<size_t>(comps.count), -1);
      for (Index j = 0; j < S.m; ++j) {
        const int c = comps.vertex_component[groups[j].front()];
        if (best[c] < 0 || groups[j].size() < groups[best[c]].size()) best[c] = j;
      }
      for (Index j : best)
        if (j >= 0)
          for (int a = 0; a < 3; ++a) sub.augment_columns.push_back(3 * j + a);
      for (Index c = 3 * S.m; c < S.nx; ++c) sub.augment_columns.push_back(c);
    }
  }

  // Order the factorization by vertex (its three coordinates together), by
  // patch (its 12 transform entries) and by element (its 4 entries of Q,
  // when kept): the quotient graph is 3–9× smaller than the unknowns' graph.
  if (sub.ordering_groups.empty()) {
    sub.ordering_groups.assign(static_cast<size_t>(S.nu), -1);
    Index group = 0;
    for (Index v = 0; v < n; ++v) {
      const Index base = S.control_of_free[v];
      if (base < 0) continue;
      for (int a = 0; a < 3; ++a) sub.ordering_groups[static_cast<size_t>(base + a)] = group;
      ++group;
    }
    for (Index p = 0; p < S.s; ++p, ++group)
      for (int c = 0; c < 12; ++c) sub.ordering_groups[static_cast<size_t>(S.patch_base + 12 * p + c)] = group;
    for (Index i = S.patch_base + 12 * S.s; i < S.nu; i += 4, ++group)
      for (Index c = i; c < std::min(i + 4, S.nu); ++c) sub.ordering_groups[static_cast<size_t>(c)] = group;
  }

  report("subspace", 0.2);
  // The assembly's freed temporaries (about 300 MB on the Bumpy Plane) would
  // otherwise stay resident under the build's peak (factor plus solution).
  release_free_heap();
  t.reset();
  summary.subspace = S.solver.precompute(Hu, C, Du, sub);
  summary.subspace_seconds = t.seconds();
  if (!summary.subspace.ok()) {
    summary.status = summary.subspace.status;
    summary.message = "variational subspace: " + summary.subspace.message;
    return summary;
  }

  // Reconstruction basis P·[N UD] and the Phase 2 matrices D_Vᵀ·P·[N UD].
  report("reduction", 0.9);
  t.reset();
  {
    // M_N, M_U = (D_Vᵀ·P)·[N UD] with the sparse 9d × n_u factor first, and
    // the float basis block by block: no 3n × p double copy of P·[N UD].
    const SparseMatrix<double> DVtP = SparseMatrix<double>(DV.transpose()) * P;
    S.MN = DVtP * S.solver.subspace().N;
    S.MU = DVtP * S.solver.subspace().UD;
    S.make_basis(P);
  }
  summary.reduction_seconds = t.seconds();

  S.finish(options);
  state_ = std::move(st);
  reset_pose();
  report("done", 1.0);

  summary.status = Status::Success;
  summary.message = "precomputed";
  summary.vertices = n;
  summary.elements = r;
  summary.rotational_proxies = state_->d;
  summary.linear_proxies = state_->m;
  summary.patches = state_->s;
  summary.reduced_size = state_->nx + 9 * state_->d;
  summary.total_seconds = total.seconds();
  return summary;
}

void Deformer::reset_pose() {
  State& S = *state_;
  for (Index i = 0; i < S.d; ++i) Eigen::Map<Eigen::Matrix3d>(S.S.data() + 9 * i).setIdentity();
  S.r0.setIdentity();
  S.x.setZero();
}

void Deformer::set_round_threads(int threads) {
  if (threads < 0) {
    throw std::invalid_argument(fmt::format("Deformer::set_round_threads: threads must be ≥ 0, got {}", threads));
  }
  state_->alternating.threads = threads;
}

ConstraintSummary Deformer::set_handles(const Handles& handles, const ConstraintOptions& options) {
  State& S = *state_;
  if (!S.ready) throw std::invalid_argument("Deformer::set_handles: call precompute first");
  Triplets ta;
  Index col = 0;
  for (size_t h = 0; h < handles.points.size(); ++h) {
    const PointHandle& ph = handles.points[h];
    if (ph.vertices.empty()) throw std::invalid_argument(fmt::format("handle {}: no vertex", h));
    if (!ph.weights.empty() && ph.weights.size() != ph.vertices.size()) {
      throw std::invalid_argument(fmt::format("handle {}: {} weights for {} vertices", h, ph.weights.size(),
                                              ph.vertices.size()));
    }
    if (ph.weights.empty() && ph.vertices.size() != 1) {
      throw std::invalid_argument(fmt::format("handle {}: a group of {} vertices needs weights", h,
                                              ph.vertices.size()));
    }
    for (size_t i = 0; i < ph.vertices.size(); ++i) {
      const Index v = ph.vertices[i];
      if (v < 0 || v >= S.n) {
        throw std::invalid_argument(fmt::format("handle {}: vertex {} outside [0, {})", h, v, S.n));
      }
      const double w = ph.weights.empty() ? 1.0 : ph.weights[i];
      if (!std::isfinite(w)) throw std::invalid_argument(fmt::format("handle {}: weight {} is not finite", h, i));
      for (int a = 0; a < 3; ++a) S.control_row(v, a, w, col + a, &ta);
    }
    col += 3;
  }
  std::vector<Index> patches = S.fixed_patches;
  std::vector<char> prescribed(static_cast<size_t>(S.s), 0);
  for (Index p : handles.patches) {
    if (p < 0 || p >= S.s) throw std::invalid_argument(fmt::format("handle patch {} outside [0, {})", p, S.s));
    if (S.patch_types[p] == PatchType::Fixed) {
      throw std::invalid_argument(fmt::format("patch {} is Fixed: it is always constrained to the rest pose", p));
    }
    if (prescribed[p]) throw std::invalid_argument(fmt::format("patch {} is prescribed twice", p));
    prescribed[p] = 1;
    patches.push_back(p);
  }
  for (Index p : patches) {
    for (int c = 0; c < 12; ++c) ta.emplace_back(S.patch_base + 12 * p + c, col + c, 1.0);
    col += 12;
  }
  // Free Rigid patches: t_s = s_c (rows 3a + c of t_s, row-major).
  std::vector<Index> tied;
  const Index tie_row0 = col;
  for (Index p = 0; p < S.s; ++p) {
    if (S.patch_types[p] != PatchType::Rigid || prescribed[p]) continue;
    tied.push_back(p);
    for (int c = 0; c < 9; ++c) ta.emplace_back(S.patch_base + 12 * p + c, col + c, 1.0);
    col += 9;
  }
  // A_r = AᵀB (col × p) row by row from rows of B kept row-major: a free
  // vertex's control row r = 3i + a is row 3·free_vertices[i] + a of the
  // float reconstruction basis P·B, a patch unknown's is in patch_rows.
  // (AᵀB on the column-major subspace touches col·p scattered cache lines:
  // about a millisecond at p ≈ 700; repeated entries simply add up.)
  Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> Ar =
      Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>::Zero(col, S.nx + 9 * S.d);
  for (const auto& e : ta) {
    const Index r = e.row();
    if (r < S.patch_base) {
      const Index v = S.free_vertices[static_cast<size_t>(r / 3)];
      Ar.row(e.col()) += e.value() * S.basis.row(3 * v + r % 3).cast<double>();
    } else {
      Ar.row(e.col()) += e.value() * S.patch_rows.row(r - S.patch_base);
    }
  }
  const ConstraintSummary cs =
      S.phase1.set_reduced_constraints(S.solver, Ar.leftCols(S.nx), Ar.rightCols(9 * S.d), options);
  // (nx × 9d, 0.8 MB at the Tree's size: only formed when there are ties;
  // frame() reads it only then.)
  if (tied.empty()) {
    S.tie_map.resize(0, 0);
  } else {
    S.tie_map.setZero(S.nx, 9 * S.d);
  }
  for (size_t i = 0; i < tied.size(); ++i) {
    const Index k = S.rigid_cluster_of_patch[tied[i]];
    for (int a = 0; a < 3; ++a)
      for (int c = 0; c < 3; ++c)
        S.tie_map.col(9 * k + 3 * c + a) += S.phase1.Mb().col(tie_row0 + 9 * static_cast<Index>(i) + 3 * a + c);
  }
  const FusedPrecision precision = S.fused_precision();
  if (tied.empty() && S.fused_inputs_plain) {
    // G_z = M_N, G_y = M_U as last time: not compared again
    S.fused.set(S.phase1, options.threads, FusedForm::Automatic, precision);
  } else if (tied.empty()) {
    S.fused.set(S.phase1, S.MN, S.MU, options.threads, FusedForm::Automatic, precision);
    S.fused_inputs_plain = true;
  } else {
    S.MU_tied = S.MU + S.MN * S.tie_map;
    S.fused.set(S.phase1, S.MN, S.MU_tied, options.threads, FusedForm::Automatic, precision);
    S.fused_inputs_plain = false;
  }
  S.tied_patches = std::move(tied);
  S.tie_row0 = tie_row0;
  S.handles = handles;
  S.rows = col;
  S.b.setZero(col);
  return cs;
}

FrameSummary Deformer::frame(const HandleTargets& targets, Vertices* out) {
  State& S = *state_;
  if (!S.ready || !S.phase1.ready()) throw std::invalid_argument("Deformer::frame: call precompute and set_handles first");
  check_size("Deformer::frame: target points", static_cast<Index>(S.handles.points.size()),
                     targets.points.rows());
  check_size("Deformer::frame: patch transforms", static_cast<Index>(S.handles.patches.size()),
                     static_cast<Index>(targets.patch_transforms.size()));
  if (targets.points.size() > 0) check_finite("Deformer::frame: target points", targets.points);
  for (size_t i = 0; i < targets.patch_transforms.size(); ++i) {
    const auto& T = targets.patch_transforms[i];
    check_finite("Deformer::frame: patch transform", T);
    const Index p = S.handles.patches[i];
    if (S.patch_types[p] == PatchType::Rigid) {
      const Eigen::Matrix3d A = T.leftCols<3>();
      const double off = (A.transpose() * A - Eigen::Matrix3d::Identity()).norm();
      if (off > 1e-6 || A.determinant() <= 0) {
        throw std::invalid_argument(fmt::format(
            "Deformer::frame: patch {} is Rigid but its transform is not a rotation (‖AᵀA − I‖ = {:.3e}, det = {:.3e})",
            p, off, A.determinant()));
      }
    }
  }
  const Timer total;
  FrameSummary summary;

  // Global rotation adaptation: r₀ from the area-weighted mean of the cluster
  // rotations; solve in the frame rotated by r₀ᵀ.
  if (S.global_rotation) {
    Eigen::Matrix3d G = Eigen::Matrix3d::Zero();
    for (Index i = 0; i < S.d; ++i) G += S.cluster_measure(i) * Eigen::Map<const Eigen::Matrix3d>(S.S.data() + 9 * i);
    S.r0 = fit_rotation(G);
  } else {
    S.r0.setIdentity();
  }
  const Eigen::Matrix3d r0t = S.r0.transpose();
  Index row = 0;
  for (Index h = 0; h < targets.points.rows(); ++h) {
    S.b.segment<3>(row) = r0t * targets.points.row(h).transpose();
    row += 3;
  }
  auto put_patch = [&](const Eigen::Matrix<double, 3, 4>& T) {
    const Eigen::Matrix3d A = r0t * T.leftCols<3>();
    const Eigen::Vector3d tr = r0t * T.col(3);
    for (int a = 0; a < 3; ++a)
      for (int c = 0; c < 3; ++c) S.b(row + 3 * a + c) = A(a, c);
    S.b.segment<3>(row + 9) = tr;
    row += 12;
  };
  const Eigen::Matrix<double, 3, 4> identity = Eigen::Matrix<double, 3, 4>::Identity();
  for (size_t i = 0; i < S.fixed_patches.size(); ++i) put_patch(identity);
  for (const auto& T : targets.patch_transforms) put_patch(T);

  for (Index i = 0; i < S.d; ++i) {
    Eigen::Map<Eigen::Matrix3d>(S.s_local.data() + 9 * i) = r0t * Eigen::Map<const Eigen::Matrix3d>(S.S.data() + 9 * i);
  }
  Timer t;
  AlternatingOptions opts = S.alternating;
  const AlternatingSummary as = S.fused.run(S.phase1, *S.projection, S.b, opts, S.x, S.s_local);
  if (!S.tied_patches.empty()) S.x.noalias() += S.tie_map * S.s_local;  // the ties' right-hand sides
  summary.iterations = as.iterations;
  summary.last_change = as.last_change;
  summary.status = as.status;
  if (!S.x.allFinite() || !S.s_local.allFinite()) {
    summary.status = Status::NumericalFailure;
    summary.message = "the alternating rounds produced NaN or infinite reduced coordinates";
  }
  for (Index i = 0; i < S.d; ++i) {
    Eigen::Map<Eigen::Matrix3d>(S.S.data() + 9 * i) = S.r0 * Eigen::Map<const Eigen::Matrix3d>(S.s_local.data() + 9 * i);
  }
  summary.solve_seconds = t.seconds();

  // Reconstruction V′ = r₀·(P·[N UD]·[X; S_local]), parallel over vertices.
  t.reset();
  S.wf.head(S.nx) = S.x.cast<float>();
  S.wf.tail(9 * S.d) = S.s_local.cast<float>();
  if (out == nullptr) {  // the caller reconstructs (reconstruction_basis, reduced_coordinates)
    summary.total_seconds = total.seconds();
    return summary;
  }
  reconstruct_points(S.basis, S.wf, S.r0.cast<float>(), out);
  summary.reconstruct_seconds = t.seconds();
  summary.total_seconds = total.seconds();
  return summary;
}

SelDefScenario apply_sel_def(const std::vector<int>& sel, const Eigen::Matrix4d& def, DeformableMesh* model) {
  const Index n = model->V.rows();
  check_size("apply_sel_def: .sel entries", n, static_cast<Index>(sel.size()));
  check_finite("apply_sel_def: .def matrix", def);
  model->patch_types = {PatchType::Fixed, PatchType::Affine};
  model->patch_of_vertex.assign(static_cast<size_t>(n), -1);
  Index fixed = 0, handle = 0;
  for (Index v = 0; v < n; ++v) {
    switch (sel[v]) {
      case 0: model->patch_of_vertex[v] = 0; ++fixed; break;
      case 1: break;
      case 2: model->patch_of_vertex[v] = 1; ++handle; break;
      default:
        throw std::invalid_argument(fmt::format("apply_sel_def: vertex {} has role {} (expected 0, 1 or 2)", v, sel[v]));
    }
  }
  if (handle == 0) throw std::invalid_argument("apply_sel_def: the selection has no handle vertex (role 2)");
  if (fixed == 0) {
    // No fixed region: keep only the handle patch.
    model->patch_types = {PatchType::Affine};
    for (int& p : model->patch_of_vertex)
      if (p == 1) p = 0;
  }
  SelDefScenario sc;
  sc.handles.patches = {static_cast<Index>(model->patch_types.size()) - 1};
  sc.targets.points.resize(0, 3);
  sc.targets.patch_transforms = {def.topRows<3>()};
  return sc;
}

}  // namespace qpreduce::deform
