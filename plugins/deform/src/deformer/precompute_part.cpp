// Deformer::precompute_part's assembly: this process's rows of the control
// system (precompute_internal.h), Q eliminated or kept.
#include "precompute_internal.h"

#include "energy/sparse_products.h"

#include <qpreduce/checks.h>

#include <fmt/format.h>

#include <algorithm>
#include <iterator>
#include <optional>
#include <tuple>
#include <utility>

namespace qpreduce::deform::detail {

// ---- The distributed assembly (Deformer::precompute_part) ----
//
// E′ with Q eliminated is a sum over rotation elements, and an element only
// reaches the rows of its own vertices: a free vertex's 3 control rows, or
// its patch's 12. A process therefore assembles
//   owned   the elements whose lowest free control row it owns (elements of
//           patch vertices only: a block of them by index), each element
//           owned by exactly one process;
//   ghosts  the other elements with a vertex whose free rows it owns.
// Its free rows of H_u and D_u are complete over owned + ghosts; the patch
// unknowns' rows gather every element with a patch vertex, so each process
// forms them from its owned elements and they are summed over the processes
// (dense on the columns they can reach, 12s × |J|), as is K.

struct ElementSplit {
  std::vector<Index> owned, ghosts;  // ascending element indices
};

ElementSplit split_elements(const Model& model, ControlRows rows, Deformer::Partition part) {
  const RotationElements& el = model.elements;
  const Index r = el.size();
  ElementSplit split;
  for (Index k = 0; k < r; ++k) {
    if (el.offsets[k] == el.offsets[k + 1]) continue;  // no edges, no energy
    Index lowest = -1;
    bool reaches_mine = false;
    for (Index e = el.offsets[k]; e < el.offsets[k + 1]; ++e)
      for (const Index v : {Index(el.edge_i[e]), Index(el.edge_j[e])}) {
        const Index c = model.control_of_free[v];
        if (c < 0) continue;
        if (lowest < 0 || c < lowest) lowest = c;
        if (c + 3 > rows.first && c < rows.end) reaches_mine = true;
      }
    const bool owned = lowest >= 0 ? lowest >= rows.first && lowest < rows.end
                                   : k * part.processes / r == part.process;
    if (owned) {
      split.owned.push_back(k);
    } else if (reaches_mine) {
      split.ghosts.push_back(k);
    }
  }
  return split;
}

// E′ on the elements `which` (ascending), Q eliminated: H, D_s, D_V over the
// 3n vertex rows and K, the sums of those elements' terms.
EliminatedArapSystem eliminated_on(const Model& model, const DeformableMesh& mesh, const std::vector<Index>& which) {
  const Index nv = 3 * model.n, c9 = 9 * model.d;
  if (which.empty()) {
    EliminatedArapSystem none;
    none.H.resize(nv, nv);
    none.Ds.resize(nv, c9);
    none.DV.resize(nv, c9);
    none.K.resize(c9, c9);
    return none;
  }
  std::vector<int> labels(which.size());
  for (size_t i = 0; i < which.size(); ++i) labels[i] = model.clusters[static_cast<size_t>(which[i])];
  ModifiedArapSystem sys =
      model.energy_model->assemble(mesh.V, select_elements(model.elements, which), labels, model.d);
  check_size("DeformationModel::assemble: L rows (selected elements)", nv + 4 * static_cast<Index>(which.size()),
             sys.L.rows());
  check_size("DeformationModel::assemble: D columns", c9, sys.D.cols());
  return eliminate_rotation_corrections(sys);
}

// Calls f(chunk) on `which` (ascending) in about eight chunks of at least
// 1,024 elements: an assembly's temporaries (a chunk's whole system and its
// products) are then a chunk's, not those of all the process's elements,
// which were its assembly's peak.
template <class F>
void for_each_chunk(const std::vector<Index>& which, F&& f) {
  const size_t chunk_size = std::max<size_t>(1024, (which.size() + 7) / 8);
  for (size_t b = 0; b < which.size(); b += chunk_size) {
    f(std::vector<Index>(which.begin() + static_cast<std::ptrdiff_t>(b),
                         which.begin() + static_cast<std::ptrdiff_t>(std::min(b + chunk_size, which.size()))));
  }
}

// *to += *from; *from is freed.
void add_sparse(SparseMatrix<double>* to, SparseMatrix<double>* from) {
  SparseMatrix<double> total = *to + *from;
  to->swap(total);
  free_sparse(from);
}

// Adds E′ on the elements `which` (ascending) to *sum, Q eliminated, chunk
// by chunk (for_each_chunk). D_V only when `with_dv` (the paper's Phase 2),
// K only while *sum still has it.
void add_eliminated(const Model& model, const DeformableMesh& mesh, const std::vector<Index>& which, bool with_dv,
                    EliminatedArapSystem* sum) {
  for_each_chunk(which, [&](const std::vector<Index>& chunk) {
    EliminatedArapSystem part = eliminated_on(model, mesh, chunk);
    add_sparse(&sum->H, &part.H);
    add_sparse(&sum->Ds, &part.Ds);
    if (sum->K.rows() > 0) add_sparse(&sum->K, &part.K);
    if (with_dv) add_sparse(&sum->DV, &part.DV);
  });
}

// Whether the model's L_QQ is block diagonal, from one element's assembly.
bool q_separable(const Model& model, const DeformableMesh& mesh) {
  const RotationElements& el = model.elements;
  for (Index k = 0; k < el.size(); ++k) {
    if (el.offsets[k] == el.offsets[k + 1]) continue;
    const std::vector<int> label{model.clusters[static_cast<size_t>(k)]};
    return model.energy_model->assemble(mesh.V, select_elements(el, {k}), label, model.d).q_separable;
  }
  return true;
}

// Sparse rows → dense on the columns `col` maps (−1: never reached).
Matrix<double> dense_on(const SparseMatrix<double>& A, const std::vector<Index>& col, Index width) {
  Matrix<double> out = Matrix<double>::Zero(A.rows(), width);
  for (Index c = 0; c < A.outerSize(); ++c)
    for (SparseMatrix<double>::InnerIterator it(A, c); it; ++it) {
      const Index j = col.empty() ? c : col[static_cast<size_t>(c)];
      if (j < 0) throw std::logic_error("distributed assembly: a patch row reached an unexpected column");
      out(it.row(), j) += it.value();
    }
  return out;
}

// The rows [first, end) of a control-layer matrix (width columns): the rows
// of `base` (its first base->rows(), which must be complete except for the
// patch unknowns' rows, skipped), then the patch rows from the summed
// `patch` (12s × |cols| on the columns `cols`, or all columns when empty).
// Built column by column into reserved space: triplets of the free rows
// (16 bytes an entry, and setFromTriplets' own copy) were the distributed
// assembly's peak. `base` is freed.
SparseMatrix<double> with_patch_rows(const Model& model, ControlRows rows, SparseMatrix<double>* base,
                                     const Matrix<double>& patch, const std::vector<Index>& cols) {
  const Index width = base->cols(), patch_end = model.patch_base + 12 * model.s;
  const Index patch_first = std::max(rows.first, model.patch_base), patch_last = std::min(rows.end, patch_end);
  const auto in_patch = [&](Index i) { return rows.first + i >= model.patch_base && rows.first + i < patch_end; };
  if (patch_first >= patch_last && base->rows() == rows.count()) {  // no patch row here
    SparseMatrix<double> out;
    out.swap(*base);
    return out;
  }
  const auto column = [&](Index j) { return cols.empty() ? j : cols[static_cast<size_t>(j)]; };
  Eigen::VectorXi per_column = Eigen::VectorXi::Zero(width);
  for (Index c = 0; c < width; ++c)
    for (SparseMatrix<double>::InnerIterator it(*base, c); it; ++it) per_column(c) += in_patch(it.row()) ? 0 : 1;
  for (Index i = patch_first; i < patch_last; ++i)
    for (Index j = 0; j < patch.cols(); ++j)
      if (patch(i - model.patch_base, j) != 0.0) ++per_column(column(j));
  SparseMatrix<double> out(rows.count(), width);
  out.reserve(per_column);
  for (Index c = 0; c < width; ++c)
    for (SparseMatrix<double>::InnerIterator it(*base, c); it; ++it)
      if (!in_patch(it.row())) out.insert(it.row(), c) = it.value();
  free_sparse(base);
  for (Index j = 0; j < patch.cols(); ++j)
    for (Index i = patch_first; i < patch_last; ++i) {
      const double v = patch(i - model.patch_base, j);
      if (v != 0.0) out.insert(i - rows.first, column(j)) = v;
    }
  out.makeCompressed();
  return out;
}

// The rows [first, end) of Pᵀ·X·R (X 3n × w; R = `right`, or I when null)
// for this process (Q eliminated: control rows only): its free rows from X
// (complete over owned + ghosts), then its patch rows from the summed
// `patch` (with_patch_rows).
SparseMatrix<double> owned_control_rows(const Model& model, ControlRows rows, const SparseMatrix<double>& P,
                                        const SparseMatrix<double>& X, const Matrix<double>& patch,
                                        const std::vector<Index>& cols, const SparseMatrix<double>* right = nullptr) {
  const Index free_end = std::min(rows.end, model.patch_base);
  const Index free_count = std::max<Index>(free_end - rows.first, 0);
  const Index width = right != nullptr ? right->cols() : X.cols();
  SparseMatrix<double> free_rows(free_count, width);
  if (free_count > 0) {
    const SparseMatrix<double> PfT = P.middleCols(rows.first, free_count).transpose();
    free_rows = detail::parallel_product(PfT, X);
    if (right != nullptr) {
      SparseMatrix<double> times_right = detail::parallel_product(free_rows, *right);
      free_rows.swap(times_right);
    }
  }
  return with_patch_rows(model, rows, &free_rows, patch, cols);
}

// Whether element k has a vertex in a patch (its energy reaches patch rows).
bool has_patch_vertex(const Model& model, Index k) {
  const RotationElements& el = model.elements;
  for (Index e = el.offsets[k]; e < el.offsets[k + 1]; ++e)
    if (model.control_of_free[el.edge_i[e]] < 0 || model.control_of_free[el.edge_j[e]] < 0) return true;
  return false;
}

// The control columns a patch unknown's row of H_u can reach: every column
// of a vertex of an element with a patch vertex, and that element's 4
// columns of Q when Q is kept in u (ascending), and the map column →
// position (−1 elsewhere).
void patch_row_columns(const Model& model, std::vector<Index>* cols, std::vector<Index>* position) {
  const RotationElements& el = model.elements;
  std::vector<char> reach(static_cast<size_t>(model.nu), 0);
  const auto mark_vertex = [&](Index v) {
    const Index c = model.control_of_free[v];
    const Index first = c >= 0 ? c : model.patch_base + 12 * model.patch_of_vertex[static_cast<size_t>(v)];
    for (Index j = first; j < first + (c >= 0 ? 3 : 12); ++j) reach[static_cast<size_t>(j)] = 1;
  };
  for (Index k = 0; k < el.size(); ++k) {
    if (!has_patch_vertex(model, k)) continue;
    for (Index e = el.offsets[k]; e < el.offsets[k + 1]; ++e) {
      mark_vertex(el.edge_i[e]);
      mark_vertex(el.edge_j[e]);
    }
    const Index q = model.patch_base + 12 * model.s + 4 * k;  // element k's Q, when kept
    if (model.keep_q)
      for (Index j = q; j < q + 4; ++j) reach[static_cast<size_t>(j)] = 1;
  }
  cols->clear();
  position->assign(static_cast<size_t>(model.nu), -1);
  for (Index j = 0; j < model.nu; ++j)
    if (reach[static_cast<size_t>(j)]) {
      (*position)[static_cast<size_t>(j)] = static_cast<Index>(cols->size());
      cols->push_back(j);
    }
}

// K (9d × 9d, a 9 × 9 block per cluster) summed over the processes as 9 × 9d.
SparseMatrix<double> summed_cluster_blocks(const SparseMatrix<double>& K, Index d,
                                           const Deformer::SumOverProcesses& sum) {
  Matrix<double> blocks = Matrix<double>::Zero(9, 9 * d);
  for (Index c = 0; c < K.outerSize(); ++c)
    for (SparseMatrix<double>::InnerIterator it(K, c); it; ++it) {
      if (it.row() / 9 != c / 9) throw std::logic_error("distributed assembly: K is not 9 × 9 block diagonal");
      blocks(it.row() % 9, c) += it.value();
    }
  sum(&blocks);
  Triplets t;
  for (Index c = 0; c < 9 * d; ++c)
    for (Index a = 0; a < 9; ++a)
      if (blocks(a, c) != 0.0) t.emplace_back(9 * (c / 9) + a, c, blocks(a, c));
  SparseMatrix<double> out(9 * d, 9 * d);
  out.setFromTriplets(t.begin(), t.end());
  return out;
}

// This process's rows of the control system (Q eliminated), assembled on
// its owned and ghost elements; *assembled counts them.
ControlSystem control_system_rows(const Model& model, const DeformableMesh& mesh, ControlRows rows,
                                  Deformer::Partition part, ClusterRotationFit fit,
                                  const Deformer::SumOverProcesses& sum, Index* assembled) {
  const ElementSplit split = split_elements(model, rows, part);
  *assembled = static_cast<Index>(split.owned.size() + split.ghosts.size());
  ControlSystem cs;
  cs.P = model.control_matrix();
  const bool with_dv = fit == ClusterRotationFit::PaperPhase2;
  EliminatedArapSystem own = eliminated_on(model, mesh, {});  // zero, of the right shapes
  add_eliminated(model, mesh, split.owned, with_dv, &own);
  cs.K = summed_cluster_blocks(own.K, model.d, sum);
  free_sparse(&own.K);
  // The patch unknowns' rows, from the owned elements, summed.
  Matrix<double> patch_H, patch_D, patch_DV;
  std::vector<Index> cols, position;
  if (model.s > 0) {
    patch_row_columns(model, &cols, &position);
    const SparseMatrix<double> PpT = cs.P.rightCols(12 * model.s).transpose();  // 12s × 3n
    patch_H = dense_on(detail::parallel_product(PpT, own.H) * cs.P, position, static_cast<Index>(cols.size()));
    patch_D = dense_on(PpT * own.Ds, {}, 9 * model.d);
    sum(&patch_H);
    sum(&patch_D);
    if (with_dv) {
      patch_DV = dense_on(PpT * own.DV, {}, 9 * model.d);
      sum(&patch_DV);
    }
  }
  add_eliminated(model, mesh, split.ghosts, with_dv, &own);  // the free rows complete
  cs.Hu = owned_control_rows(model, rows, cs.P, own.H, patch_H, cols, &cs.P);
  free_sparse(&own.H);
  cs.Du = owned_control_rows(model, rows, cs.P, own.Ds, patch_D, {});
  if (with_dv) cs.DV = owned_control_rows(model, rows, cs.P, own.DV, patch_DV, {});
  return cs;
}

namespace {

// The elements whose assembly completes this process's rows of Q (those
// from q0 on, 4 per element): the elements of those rows and their
// neighbours, sorted; empty when the process holds no row of Q.
std::vector<Index> q_row_elements(const RotationElements& el, const ControlRows& rows, Index q0) {
  std::vector<Index> out;
  if (rows.end <= q0) return out;
  const Index r = el.size();
  std::vector<char> keep(static_cast<size_t>(r), 0), here(static_cast<size_t>(r), 0);
  for (Index k = (std::max(rows.first, q0) - q0) / 4; k <= (rows.end - 1 - q0) / 4; ++k)
    here[static_cast<size_t>(k)] = keep[static_cast<size_t>(k)] = 1;
  for (const auto& [k, j] : element_neighbours(el)) {
    if (here[static_cast<size_t>(k)]) keep[static_cast<size_t>(j)] = 1;
    if (here[static_cast<size_t>(j)]) keep[static_cast<size_t>(k)] = 1;
  }
  for (Index k = 0; k < r; ++k)
    if (keep[static_cast<size_t>(k)]) out.push_back(k);
  return out;
}

}  // namespace

// ---- γ > 0: Q kept in u = [control (patch_base + 12s); Q (4r)] ----
//
// The moving-frame term (Eq. 11) couples neighbouring elements' Q, so the
// blocks are no longer sums over elements alone; a process's rows are still
// complete on a subset of them:
//   a free vertex's rows    every element with that vertex (owned + ghosts);
//   element k's rows of Q   k and its neighbours (element_neighbours), whose
//                           pairs select_elements keeps;
// all assembled in one piece. The patch unknowns' rows are summed over the
// processes from each one's owned elements with a patch vertex (the pairs
// reach no patch row). K is empty: Q is not eliminated.
ControlSystem kept_q_control_rows(Model& model, const DeformableMesh& mesh, Deformer::Partition part,
                                  ClusterRotationFit fit, const Deformer::SumOverProcesses& sum, Index* assembled) {
  model.keep_rotation_corrections();
  const ControlRows rows = control_rows(model.nu, part);
  const RotationElements& el = model.elements;
  const Index q0 = model.patch_base + 12 * model.s, c9 = 9 * model.d;
  const bool with_dv = fit == ClusterRotationFit::PaperPhase2;
  ControlSystem cs;
  cs.P = model.control_matrix();
  const ElementSplit split = split_elements(model, rows, part);
  const auto blocks_on = [&](const std::vector<Index>& which) {
    std::vector<int> labels(which.size());
    for (size_t i = 0; i < which.size(); ++i) labels[i] = model.clusters[static_cast<size_t>(which[i])];
    const ModifiedArapSystem sys = model.energy_model->assemble(mesh.V, select_elements(el, which), labels, model.d);
    return kept_q_blocks(model, sys, cs.P, &which);
  };
  // The patch rows, [patch_base, q0): from the owned elements with a patch vertex, summed.
  Matrix<double> patch_H, patch_D, patch_DV;
  std::vector<Index> cols, position;
  if (model.s > 0) {
    std::vector<Index> with_patch;
    for (const Index k : split.owned)
      if (has_patch_vertex(model, k)) with_patch.push_back(k);
    const ControlSystem own = blocks_on(with_patch);
    patch_row_columns(model, &cols, &position);
    patch_H = dense_on(own.Hu.middleRows(model.patch_base, 12 * model.s), position, static_cast<Index>(cols.size()));
    patch_D = dense_on(own.Du.middleRows(model.patch_base, 12 * model.s), {}, c9);
    sum(&patch_H);
    sum(&patch_D);
    if (with_dv) {
      const SparseMatrix<double> PpT = cs.P.middleCols(model.patch_base, 12 * model.s).transpose();  // 12s × 3n
      patch_DV = dense_on(PpT * own.DV, {}, c9);
      sum(&patch_DV);
    }
  }
  // This process's rows of H_u, D_u and PᵀD_V: the free vertex rows from
  // owned + ghosts chunk by chunk, the rows of Q from one assembly on their
  // elements and those elements' neighbours; each keeps only its own rows.
  SparseMatrix<double> H(rows.count(), model.nu), D(rows.count(), c9), DV(rows.count(), c9);
  const SparseMatrix<double> PrT = cs.P.middleCols(rows.first, rows.count()).transpose();  // count × 3n
  const auto add_rows = [&](const std::vector<Index>& which, bool vertex_rows) {
    ControlSystem b = blocks_on(which);
    const auto mine = [&](const SparseMatrix<double>& A) {
      SparseMatrix<double> out = A.middleRows(rows.first, rows.count());
      out.prune([&](Index i, Index, double) { return (rows.first + i < model.patch_base) == vertex_rows; });
      return out;
    };
    SparseMatrix<double> Hb = mine(b.Hu), Db = mine(b.Du);
    free_sparse(&b.Hu);
    add_sparse(&H, &Hb);
    add_sparse(&D, &Db);
    if (with_dv && vertex_rows) {  // P is zero on Q's columns: PᵀD_V has no row of Q
      SparseMatrix<double> DVb = PrT * b.DV;
      add_sparse(&DV, &DVb);
    }
  };
  std::vector<Index> vertex_elements = split.owned;
  vertex_elements.insert(vertex_elements.end(), split.ghosts.begin(), split.ghosts.end());
  std::sort(vertex_elements.begin(), vertex_elements.end());
  for_each_chunk(vertex_elements, [&](const std::vector<Index>& chunk) { add_rows(chunk, true); });
  const std::vector<Index> q_elements = q_row_elements(el, rows, q0);
  if (!q_elements.empty()) add_rows(q_elements, false);
  std::vector<Index> both;
  std::set_union(vertex_elements.begin(), vertex_elements.end(), q_elements.begin(), q_elements.end(),
                 std::back_inserter(both));
  *assembled = static_cast<Index>(both.size());
  cs.Hu = with_patch_rows(model, rows, &H, patch_H, cols);
  cs.Du = with_patch_rows(model, rows, &D, patch_D, {});
  if (with_dv) cs.DV = with_patch_rows(model, rows, &DV, patch_DV, {});
  return cs;
}

// The whole control system, then this process's rows: one process (K = 1)
// holds the whole system anyway.
ControlSystem whole_then_rows(Model& model, const DeformableMesh& mesh, Deformer::Partition part,
                              ClusterRotationFit fit) {
  ControlSystem cs = assemble_control_system(model, mesh);
  const ControlRows rows = control_rows(model.nu, part);
  cs.Hu = SparseMatrix<double>(cs.Hu.middleRows(rows.first, rows.count()));
  cs.Du = SparseMatrix<double>(cs.Du.middleRows(rows.first, rows.count()));
  if (fit == ClusterRotationFit::PaperPhase2) {  // rows of PᵀD_V (P is zero on Q's columns, as in phase2_left)
    const SparseMatrix<double> PrT = cs.P.middleCols(rows.first, rows.count()).transpose();  // count × 3n
    cs.DV = PrT * cs.DV;
  } else {
    free_sparse(&cs.DV);  // only the paper's Phase 2 reads it
  }
  return cs;
}

}  // namespace qpreduce::deform::detail
