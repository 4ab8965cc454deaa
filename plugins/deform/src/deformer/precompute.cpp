// Deformer::precompute, in the order of the paper's algorithm (Sections 4–5):
// rotational clusters and linear proxies, the energy in the control layer,
// the variational subspace (Eq. 14–15), the reduced operators of Phase 2 and
// the reconstruction, and the Phase 1 preparation (State::finish).
#include "qpreduce/deform/deformer/deformer.h"

#include "precompute_internal.h"
#include "energy/sparse_products.h"
#include "state.h"

#include <qpreduce/checks.h>
#include <qpreduce/util/timer.h>
#include <qpreduce/util/heap.h>

#include <fmt/format.h>

#include <algorithm>
#include <iterator>
#include <optional>
#include <tuple>
#include <utility>

namespace qpreduce::deform {
namespace {

using detail::CompactMesh;
using detail::Model;
using detail::Triplets;
using detail::Groups;
using detail::ControlRows;
using detail::ControlSystem;
using detail::control_rows;
using detail::free_sparse;
using detail::whole_then_rows;
using detail::q_separable;
using detail::control_system_rows;
using detail::kept_q_control_rows;
using detail::kept_q_blocks;
using detail::assemble_control_system;

// The mesh the automatic proxies are placed on: the referenced part (a
// compacted copy when some vertex is unreferenced, else the mesh itself).
struct ProxyMesh {
  const CompactMesh* compact;  // null: the mesh itself
  VerticesRef V;
  ElementsRef E;
};

// The rotational clusters: the mesh's labels, or clusters of the referenced
// part (surfaces: one label per vertex; an unreferenced vertex is an element
// without edges, labelled 0); then each Rigid patch's own. Returns false with
// *summary set when the clustering fails.
bool make_rotation_clusters(Model& model, const DeformableMesh& mesh, const DeformerOptions& options,
                            const ProxyMesh& pm, PrecomputeSummary* summary) {
  const Index r = model.elements.size();
  if (!mesh.clusters.empty()) {
    check_size("DeformableMesh::clusters size", r, static_cast<Index>(mesh.clusters.size()));
    for (Index k = 0; k < r; ++k) {
      if (mesh.clusters[k] < 0) {
        throw std::invalid_argument(fmt::format("DeformableMesh::clusters: element {} has negative label {}", k,
                                                mesh.clusters[k]));
      }
    }
    model.set_clusters(mesh.clusters, 1 + *std::max_element(mesh.clusters.begin(), mesh.clusters.end()));
  } else {
    const bool tet = mesh.is_tet();
    Clustering clustering;
    const ClusterSummary cs =
        compute_rotation_clusters(pm.V, pm.E, tet ? ClusterElement::Element : ClusterElement::Vertex,
                                  options.rotational_proxies, options.clustering, &clustering);
    if (!cs.ok()) {
      summary->status = cs.status;
      summary->message = "rotational clusters: " + cs.message;
      return false;
    }
    std::vector<int> labels = std::move(clustering.labels);
    if (!tet && pm.compact) {
      std::vector<int> full(static_cast<size_t>(model.n), 0);
      for (size_t i = 0; i < pm.compact->old_of_new.size(); ++i)
        full[static_cast<size_t>(pm.compact->old_of_new[i])] = labels[i];
      labels = std::move(full);
    }
    model.set_clusters(std::move(labels), clustering.count);
  }
  model.separate_rigid_clusters(mesh.T);
  return true;
}

// The linear proxy groups (the mesh's, or farthest-point samples of the
// referenced part in original indices), restricted to free vertices; sets m
// and nx.
Groups make_linear_proxies(Model& model, const DeformableMesh& mesh, const DeformerOptions& options,
                           const ProxyMesh& pm) {
  LinearProxies proxies = mesh.linear;
  if (proxies.count() == 0) {
    proxies = linear_proxies_fps(pm.V, pm.E, options.linear_proxies);
    if (pm.compact)
      for (auto& g : proxies.groups)
        for (Index& v : g) v = pm.compact->old_of_new[static_cast<size_t>(v)];
  }
  const Index n = model.n;
  Groups groups;
  for (const auto& g : proxies.groups) {
    std::vector<Index> kept;
    for (Index v : g) {
      if (v < 0 || v >= n) throw std::invalid_argument(fmt::format("linear proxies: vertex {} outside [0, {})", v, n));
      if (model.control_of_free[v] >= 0) kept.push_back(v);
    }
    if (!kept.empty()) groups.push_back(std::move(kept));
  }
  model.m = static_cast<Index>(groups.size());
  model.nx = 3 * model.m + 12 * model.s;
  return groups;
}

// Every connected component needs a proxy or a patch, else the KKT system
// (Eq. 14) is singular. Throws std::invalid_argument naming the component.
void check_components_pinned(const Model& model, const Groups& groups) {
  const MeshComponents& comps = model.components;
  std::vector<char> pinned(static_cast<size_t>(comps.count), 0);
  for (const auto& g : groups)
    for (Index v : g) pinned[static_cast<size_t>(comps.vertex_component[v])] = 1;
  for (Index v = 0; v < model.n; ++v)
    if (model.control_of_free[v] < 0) pinned[static_cast<size_t>(comps.vertex_component[v])] = 1;
  for (Index c = 0; c < comps.count; ++c) {
    if (!pinned[c]) {
      throw std::invalid_argument(fmt::format(
          "DeformableMesh: connected component {} of {} has no linear proxy and no patch; the KKT system (Eq. 14) "
          "would be singular (use at least {} linear proxies, or patch that component)",
          c, comps.count, comps.count));
    }
  }
}

// The energy in the control layer u: E(u, S) = ½uᵀH_u u − Sᵀ D_uᵀ u + c(S),
// with D_V the rotational term of V′ (the paper's Phase 2), K the S-term of
// the eliminated Q (the exact Phase 2, arap_energy.h), and P.
// Q eliminated (the model's L_QQ is block diagonal): H_u = PᵀHP, D_u = PᵀD_s.
// The full system and each product's input go as soon as they are used:
// these products are the assembly's peak (on a 160k-vertex surface each
// 3n × 3n matrix is a few hundred MB).
// (Eigen 3.4's SparseMatrix has no move operations and keeps its storage on
// assignment from an empty matrix: swap with an empty one frees it.)
ControlSystem eliminated_control_system(const Model& model, ModifiedArapSystem* full) {
  ControlSystem cs;
  EliminatedArapSystem elim = eliminate_rotation_corrections(*full);
  free_sparse(&full->L);
  free_sparse(&full->D);
  cs.P = model.control_matrix();
  if (detail::is_identity(cs.P)) {  // every vertex free, no patch: u = V′
    cs.Hu = std::move(elim.H);
    cs.Du = std::move(elim.Ds);
  } else {
    const SparseMatrix<double> Pt = cs.P.transpose();
    SparseMatrix<double> HP = detail::parallel_product(elim.H, cs.P);
    free_sparse(&elim.H);
    cs.Hu = detail::parallel_product(Pt, HP);
    free_sparse(&HP);
    cs.Du = detail::parallel_product(Pt, elim.Ds);
  }
  cs.DV = std::move(elim.DV);
  cs.K = std::move(elim.K);
  return cs;
}

// Q kept: u = [control (patch_base + 12s); Q (4r)]. The model's blocks on
// the elements `which` (ascending; null: all of them, in order) in the
// control layer: H_u = P̂ᵀ·L·P̂ (symmetrised), D_u = P̂ᵀ·D (n_u × 9d) and
// D_V = D's vertex rows (3n × 9d), where P̂ ((3n + 4|which|) × n_u) is
// blockdiag(P, I): the subset's [V′; Q] from u. P: control_matrix().
}  // namespace

ControlSystem detail::kept_q_blocks(const Model& model, const ModifiedArapSystem& sys,
                                             const SparseMatrix<double>& P, const std::vector<Index>* which) {
  const Index nv = 3 * model.n, w = which != nullptr ? static_cast<Index>(which->size()) : model.elements.size();
  const Index q0 = model.patch_base + 12 * model.s;
  check_size("DeformationModel::assemble: L rows", nv + 4 * w, sys.L.rows());
  check_size("DeformationModel::assemble: D columns", 9 * model.d, sys.D.cols());
  SparseMatrix<double> Phat(nv + 4 * w, model.nu);
  {
    Triplets tp;
    tp.reserve(static_cast<size_t>(P.nonZeros() + 4 * w));
    for (Index c = 0; c < P.outerSize(); ++c)
      for (SparseMatrix<double>::InnerIterator it(P, c); it; ++it) tp.emplace_back(it.row(), c, it.value());
    for (Index i = 0; i < w; ++i) {
      const Index k = which != nullptr ? (*which)[static_cast<size_t>(i)] : i;
      for (int c = 0; c < 4; ++c) tp.emplace_back(nv + 4 * i + c, q0 + 4 * k + c, 1.0);
    }
    Phat.setFromTriplets(tp.begin(), tp.end());
  }
  const SparseMatrix<double> PhatT = Phat.transpose();
  ControlSystem cs;
  cs.Hu = PhatT * sys.L * Phat;
  cs.Hu = 0.5 * (cs.Hu + SparseMatrix<double>(cs.Hu.transpose()));
  cs.Du = PhatT * sys.D;
  cs.DV = sys.D.topRows(nv);
  return cs;
}

namespace {

// Q kept, the whole system: [V′; Q] = blockdiag(P_V, I)·u.
ControlSystem kept_q_control_system(Model& model, const ModifiedArapSystem& full) {
  model.keep_rotation_corrections();
  const SparseMatrix<double> P = model.control_matrix();
  ControlSystem cs = kept_q_blocks(model, full, P, nullptr);
  cs.P = P;
  return cs;
}

// The model's energy (Q eliminated when L_QQ is block diagonal), then the
// control layer. The full system is freed before the factorization.
}  // namespace

ControlSystem detail::assemble_control_system(Model& model, const DeformableMesh& mesh) {
  ModifiedArapSystem full = model.energy_model->assemble(mesh.V, model.elements, model.clusters, model.d);
  check_size("DeformationModel::assemble: L rows", 3 * model.n + 4 * model.elements.size(), full.L.rows());
  check_size("DeformationModel::assemble: D columns", 9 * model.d, full.D.cols());
  if (full.q_separable) return eliminated_control_system(model, &full);
  return kept_q_control_system(model, full);
}

namespace {

// C (n_u × nx): the linear proxies (group means of free vertices, Ŵ ⊗ I₃)
// and the patch unknowns (Eq. 47) as columns of the constraint matrix.
SparseMatrix<double> proxy_selection(const Model& model, const Groups& groups) {
  Triplets tc;
  for (Index j = 0; j < model.m; ++j) {
    const double w = 1.0 / static_cast<double>(groups[j].size());
    for (Index v : groups[j])
      for (int a = 0; a < 3; ++a) tc.emplace_back(model.control_of_free[v] + a, 3 * j + a, w);
  }
  for (Index p = 0; p < model.s; ++p)
    for (int c = 0; c < 12; ++c) tc.emplace_back(model.patch_base + 12 * p + c, 3 * model.m + 12 * p + c, 1.0);
  SparseMatrix<double> C(model.nu, model.nx);
  C.setFromTriplets(tc.begin(), tc.end());
  return C;
}

// Augment with the cheapest columns: every patch column (one entry each) and,
// when groups are long, only the shortest group's three columns of each
// component (one group per component suffices).
void choose_augment_columns(const Model& model, const Groups& groups, double hu_nonzeros, SubspaceOptions* sub) {
  double fill = 0.0;
  for (const auto& g : groups) fill += 3.0 * static_cast<double>(g.size() * g.size());
  if (!(fill > sub->max_augmentation_fill * hu_nonzeros && model.m > 0)) return;
  const MeshComponents& comps = model.components;
  std::vector<Index> best(static_cast<size_t>(comps.count), -1);
  for (Index j = 0; j < model.m; ++j) {
    const int c = comps.vertex_component[groups[j].front()];
    if (best[c] < 0 || groups[j].size() < groups[best[c]].size()) best[c] = j;
  }
  for (Index j : best)
    if (j >= 0)
      for (int a = 0; a < 3; ++a) sub->augment_columns.push_back(3 * j + a);
  for (Index c = 3 * model.m; c < model.nx; ++c) sub->augment_columns.push_back(c);
}

// Order the factorization by vertex (its three coordinates together), by
// patch (its 12 transform entries) and by element (its 4 entries of Q, when
// kept): the quotient graph is three to nine times smaller than the unknowns'
// graph.
void choose_ordering_groups(const Model& model, SubspaceOptions* sub) {
  const Index nu = model.nu;
  sub->ordering_groups.assign(static_cast<size_t>(nu), -1);
  Index group = 0;
  for (Index v = 0; v < model.n; ++v) {
    const Index base = model.control_of_free[v];
    if (base < 0) continue;
    for (int a = 0; a < 3; ++a) sub->ordering_groups[static_cast<size_t>(base + a)] = group;
    ++group;
  }
  for (Index p = 0; p < model.s; ++p, ++group)
    for (int c = 0; c < 12; ++c) sub->ordering_groups[static_cast<size_t>(model.patch_base + 12 * p + c)] = group;
  for (Index i = model.patch_base + 12 * model.s; i < nu; i += 4, ++group)
    for (Index c = i; c < std::min(i + 4, nu); ++c) sub->ordering_groups[static_cast<size_t>(c)] = group;
}

// The engine's subspace options for this model: the user's, with the
// augmentation columns and the ordering groups filled in when not given.
SubspaceOptions subspace_options(const Model& model, const DeformerOptions& options, const Groups& groups,
                                 double hu_nonzeros) {
  SubspaceOptions sub = options.subspace;
  // The deformer never sets constraints on the SubspaceSolver (Phase 1 has
  // its own fast path on H_zz): no p × p eigendecomposition for it.
  sub.prepare_constraint_path = false;
  // Phase 1 holds the rotational coordinates fixed (y = S), so U·D need not
  // have full rank: rotations whose effect the linear proxies or patches
  // already pin (all of them, with a proxy at every vertex) are legitimate.
  sub.check_dependent_cd = false;
  if (sub.augment_columns.empty()) choose_augment_columns(model, groups, hu_nonzeros, &sub);
  if (sub.ordering_groups.empty()) choose_ordering_groups(model, &sub);
  return sub;
}

// The Phase 2 matrices' left factor, G = M_N·X + M_U·S (9d × nx, 9d × 9d),
// for the rotation step `fit` (arap_energy.h):
//   Exact        the S-coefficient of E′ at (V′, Q*): G = D_uᵀ·u + K·S, so
//                M_N = D_uᵀ·N, M_U = D_uᵀ·UD + K (D_uᵀ·u = D_sᵀ·V′ with Q
//                eliminated, D_Vᵀ·V′ + D_Qᵀ·Q with Q kept in u; K = 0 then);
//   PaperPhase2  Eq. 19: G = D_Vᵀ·V′, so M_N, M_U = (D_Vᵀ·P)·[N UD].
// The sparse 9d × n_u factor `left`; M_N = left·N, M_U = left·UD (+ K).
SparseMatrix<double> phase2_left(const ControlSystem& system, ClusterRotationFit fit) {
  return fit == ClusterRotationFit::Exact ? SparseMatrix<double>(system.Du.transpose())
                                          : SparseMatrix<double>(SparseMatrix<double>(system.DV.transpose()) * system.P);
}

// The reconstruction basis P·[N UD] (float, block by block: no 3n × p double
// copy), the Phase 2 matrices and the patch unknowns' rows; then the solver
// lets go of the double basis, which nothing after precompute reads.
void reduce_operators(Model& model, const ControlSystem& system, ClusterRotationFit fit) {
  const auto& B = model.solver.subspace();
  const SparseMatrix<double> left = phase2_left(system, fit);
  model.MN = left * B.N;
  model.MU = left * B.UD;
  if (fit == ClusterRotationFit::Exact && system.K.nonZeros() > 0) model.MU += system.K;
  model.take_patch_rows();
  model.make_basis(0, B.N, B.UD);
  model.solver.release_basis();
}

// The same from this process's rows of B (Deformer::precompute_part): every
// reduced operator is a sum over rows of B, formed on the owned rows and
// summed over the processes. The system (this process's rows) is freed once
// used. With more than one process the double rows are kept and the float
// rows made when asked (Deformer::basis_block), never the two together.
void reduce_operators_part(Model& model, ControlSystem* system, ClusterRotationFit fit,
                           Deformer::SubspacePart&& part, const Deformer::SumOverProcesses& sum,
                           const SubspaceOptions& sub) {
  const Index b = part.first_row, rows = part.N_rows.rows(), p = model.nx + 9 * model.d;
  {  // left's columns [b, b + rows): the system holds this process's rows
    const SparseMatrix<double> left =
        fit == ClusterRotationFit::Exact ? system->Du.transpose() : SparseMatrix<double>(system->DV.transpose());
    model.MN = left * part.N_rows;
    model.MU = left * part.UD_rows;
  }
  sum(&model.MN);
  sum(&model.MU);
  if (fit == ClusterRotationFit::Exact && system->K.nonZeros() > 0) model.MU += system->K;
  for (SparseMatrix<double>* M : {&system->Hu, &system->Du, &system->DV, &system->K, &system->P}) free_sparse(M);
  Matrix<double> patch = Matrix<double>::Zero(12 * model.s, p);
  for (Index i = 0; i < 12 * model.s; ++i) {
    const Index r = model.patch_base + i - b;
    if (r >= 0 && r < rows) patch.row(i) << part.N_rows.row(r), part.UD_rows.row(r);
  }
  sum(&patch);
  model.patch_rows = patch;
  Matrix<double> norms(p, 1);
  norms.topRows(model.nx) = part.N_rows.colwise().squaredNorm().transpose();
  norms.bottomRows(9 * model.d) = part.UD_rows.colwise().squaredNorm().transpose();
  sum(&norms);
  if (b == 0 && rows == model.nu) {  // one process: the whole float basis, usable as it is
    model.make_basis(b, part.N_rows, part.UD_rows);
    part.N_rows = Matrix<double>();
    part.UD_rows = Matrix<double>();
  } else {  // the double rows kept; float rows made when saved (Deformer::basis_block)
    model.part_held = true;
    model.part_first_row = b;
    std::tie(model.basis_first, model.part_vertex_rows) = model.vertex_rows_of(b, rows);
    model.part_N = std::move(part.N_rows);
    model.part_UD = std::move(part.UD_rows);
  }
  model.solver.restore_without_basis(model.nu, model.nx, norms.col(0).cwiseSqrt(), std::move(part.Hr),
                                     std::move(part.BtD), sub);
}

// What precompute assembles before the subspace step.
struct Assembled {
  ControlSystem system;
  SparseMatrix<double> C;
  SubspaceOptions sub;
};

// Clusters, linear proxies, the energy in the control layer (Sections 4–5).
// Returns false with *summary set when the clustering fails.
// With `sum` (precompute_part) only this process's rows of H_u and D_u.
bool assemble(const DeformableMesh& mesh, const DeformerOptions& options, const ProgressFn& progress, Model& model,
              detail::Inputs* inputs, PrecomputeSummary* summary, Assembled* out,
              Deformer::Partition partition = {}, const Deformer::SumOverProcesses& sum = {}) {
  auto report = [&](const char* stage, double f) {
    if (progress) progress(stage, f);
  };
  model.set_topology(mesh);
  *inputs = {mesh.F, mesh.T, mesh.clusters, mesh.linear.groups, options};
  model.energy_model = options.resolve_model();

  // The automatic proxies are placed on the referenced part of the mesh: a
  // compacted copy only when some vertex is unreferenced, made once.
  const ElementsRef E = mesh.is_tet() ? ElementsRef(mesh.T) : ElementsRef(mesh.F);
  std::optional<CompactMesh> compact;
  if (!model.unreferenced.empty() && (mesh.clusters.empty() || mesh.linear.count() == 0)) {
    compact = detail::compact_mesh(mesh.V, E, model.unreferenced);
  }
  const ProxyMesh pm{compact ? &*compact : nullptr, compact ? VerticesRef(compact->V) : VerticesRef(mesh.V),
                     compact ? ElementsRef(compact->E) : E};

  report("clusters", 0.0);
  Timer t;
  if (!make_rotation_clusters(model, mesh, options, pm, summary)) return false;
  summary->clustering_seconds = t.seconds();

  report("linear proxies", 0.1);
  const Groups groups = make_linear_proxies(model, mesh, options, pm);
  check_components_pinned(model, groups);

  report("energy", 0.15);
  t.reset();
  summary->assembled_elements = model.elements.size();
  double hu_nonzeros = 0.0;
  if (!sum) {
    out->system = assemble_control_system(model, mesh);
    hu_nonzeros = static_cast<double>(out->system.Hu.nonZeros());
  } else {
    // One process (K = 1) holds the whole system anyway: the single-process
    // assembly, which the distributed one is tested against.
    if (partition.processes == 1) {
      out->system = whole_then_rows(model, mesh, partition, options.rotation_fit);
    } else if (q_separable(model, mesh)) {
      out->system = control_system_rows(model, mesh, control_rows(model.nu, partition), partition,
                                        options.rotation_fit, sum, &summary->assembled_elements);
    } else {
      out->system = kept_q_control_rows(model, mesh, partition, options.rotation_fit, sum,
                                        &summary->assembled_elements);
    }
    Matrix<double> nnz(1, 1);
    nnz(0, 0) = static_cast<double>(out->system.Hu.nonZeros());
    sum(&nnz);
    hu_nonzeros = nnz(0, 0);
  }
  out->C = proxy_selection(model, groups);
  summary->assembly_seconds = t.seconds();
  out->sub = subspace_options(model, options, groups, hu_nonzeros);
  return true;
}

// A failed subspace step ends precompute with its status.
bool subspace_failed(PrecomputeSummary* summary) {
  if (summary->subspace.ok()) return false;
  summary->status = summary->subspace.status;
  summary->message = "variational subspace: " + summary->subspace.message;
  return true;
}

}  // namespace

PrecomputeSummary Deformer::precompute(const DeformableMesh& mesh, const DeformerOptions& options,
                                       const ProgressFn& progress) {
  return run_precompute(mesh, options, progress, {}, {}, {});
}

PrecomputeSummary Deformer::precompute_part(const DeformableMesh& mesh, const DeformerOptions& options,
                                            const ProgressFn& progress, Partition partition, const PartBuilder& build,
                                            const SumOverProcesses& sum) {
  if (!build || !sum) throw std::invalid_argument("Deformer::precompute_part: the builder and the sum are required");
  if (partition.processes < 1 || partition.process < 0 || partition.process >= partition.processes) {
    throw std::invalid_argument(fmt::format("Deformer::precompute_part: process {} of {} is not in [0, {})",
                                            partition.process, partition.processes, partition.processes));
  }
  if (options.double_basis && partition.processes > 1) {
    throw std::invalid_argument(
        "Deformer::precompute_part: DeformerOptions::double_basis needs the whole basis on one process (a part's "
        "rows travel and are saved in float); precompute on one process, or use the float basis");
  }
  return run_precompute(mesh, options, progress, partition, build, sum);
}

PrecomputeSummary Deformer::run_precompute(const DeformableMesh& mesh, const DeformerOptions& options,
                                           const ProgressFn& progress, Partition partition, const PartBuilder& build,
                                           const SumOverProcesses& sum) {
  std::string why;
  if (!options.is_valid(&why)) throw std::invalid_argument("DeformerOptions: " + why);
  auto report = [&](const char* stage, double f) {
    if (progress) progress(stage, f);
  };
  const Timer total;
  auto st = std::make_unique<State>();
  Model& model = st->model;
  model.double_basis = options.double_basis;
  PrecomputeSummary summary;
  Assembled as;
  const Normalization frame = normalization_of(mesh.V);
  const DeformableMesh local = normalised(mesh, frame);
  if (!assemble(local, options, progress, model, &st->inputs, &summary, &as, partition, sum)) return summary;
  model.frame = frame;

  report("subspace", 0.2);
  // The assembly's freed temporaries (about 300 MB on the Bumpy Plane) would
  // otherwise stay resident under the build's peak (factor plus solution).
  release_free_heap();
  Timer t;
  SubspacePart part;
  if (build) {
    summary.subspace = build(as.system.Hu, as.C, as.system.Du, as.sub, &part);
    if (summary.subspace.ok()) {
      check_size("Deformer::precompute_part: N_rows columns (nx)", model.nx, part.N_rows.cols());
      check_size("Deformer::precompute_part: UD_rows columns (9d)", 9 * model.d, part.UD_rows.cols());
      check_size("Deformer::precompute_part: UD_rows rows", part.N_rows.rows(), part.UD_rows.rows());
      const ControlRows mine = control_rows(model.nu, partition);
      if (part.first_row != mine.first || part.N_rows.rows() != mine.count()) {
        throw std::invalid_argument(fmt::format(
            "Deformer::precompute_part: the builder returned rows [{}, {}) of N, UD; process {} of {} owns [{}, {})",
            part.first_row, part.first_row + part.N_rows.rows(), partition.process, partition.processes, mine.first,
            mine.end));
      }
    }
    free_sparse(&as.system.Hu);  // H_r is built; H_u's rows are no longer needed
    free_sparse(&as.C);
  } else {
    summary.subspace = model.solver.precompute(as.system.Hu, as.C, as.system.Du, as.sub);
  }
  summary.subspace_seconds = t.seconds();
  if (subspace_failed(&summary)) return summary;

  report("reduction", 0.9);
  t.reset();
  if (build) {
    reduce_operators_part(model, &as.system, options.rotation_fit, std::move(part), sum, as.sub);
  } else {
    reduce_operators(model, as.system, options.rotation_fit);
  }
  summary.reduction_seconds = t.seconds();

  st->finish(options);
  state_ = std::move(st);
  reset_pose();
  report("done", 1.0);

  summary.status = Status::Success;
  summary.message = "precomputed";
  detail::describe(state_->model, &summary);
  summary.total_seconds = total.seconds();
  return summary;
}

}  // namespace qpreduce::deform
