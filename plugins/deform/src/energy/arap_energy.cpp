#include <qpreduce/checks.h>
#include "qpreduce/deform/energy/arap_energy.h"

#include "sparse_products.h"

#include <Eigen/Dense>
#include <Eigen/Eigenvalues>
#include <Eigen/SVD>
#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <cmath>

namespace qpreduce::deform {

namespace {

using Triplets = std::vector<Eigen::Triplet<double>>;
using Vec3 = Eigen::Vector3d;

Vec3 row(const Vertices& V, Index i) { return V.row(i).transpose(); }

// J(e) = [e, −[e]×]: q·e = q0·e + ω × e = J(e)·(q0, ω).
Eigen::Matrix<double, 3, 4> J_of(const Vec3& e) {
  Eigen::Matrix<double, 3, 4> J;
  J.col(0) = e;
  J(0, 1) = 0.0;   J(0, 2) = e(2);  J(0, 3) = -e(1);
  J(1, 1) = -e(2); J(1, 2) = 0.0;   J(1, 3) = e(0);
  J(2, 1) = e(1);  J(2, 2) = -e(0); J(2, 3) = 0.0;
  return J;
}

// Regulariser Hessian block (Eq. 10): 2α·a·diag(3, 2, 2, 2) + 2β·a·[[1, 0], [0, I − nnᵀ]].
Eigen::Matrix4d regulariser(double a, const EnergyParameters& p, bool surface, const Vec3& n) {
  Eigen::Matrix4d R = Eigen::Matrix4d::Zero();
  R.diagonal() << 3.0, 2.0, 2.0, 2.0;
  R *= 2.0 * p.alpha * a;
  if (surface && p.beta > 0.0) {
    Eigen::Matrix4d B = Eigen::Matrix4d::Zero();
    B(0, 0) = 1.0;
    B.bottomRightCorner<3, 3>() = Eigen::Matrix3d::Identity() - n * n.transpose();
    R += 2.0 * p.beta * a * B;
  }
  return R;
}

}  // namespace

bool EnergyParameters::is_valid(std::string* why) const {
  if (!(alpha >= 0.0) || !std::isfinite(alpha)) {
    if (why) *why = fmt::format("alpha must be finite and non-negative, got {}", alpha);
    return false;
  }
  if (!(beta >= 0.0) || !std::isfinite(beta)) {
    if (why) *why = fmt::format("beta must be finite and non-negative, got {}", beta);
    return false;
  }
  if (!(gamma >= 0.0) || !std::isfinite(gamma)) {
    if (why) *why = fmt::format("gamma must be finite and non-negative, got {}", gamma);
    return false;
  }
  if (alpha == 0.0 && beta == 0.0) {
    if (why) *why = "alpha and beta cannot both be zero: the linearised rotations q_k would be unconstrained";
    return false;
  }
  return true;
}
namespace {

// Column of s(row, col) for the basis matrices of Eq. 9 in the column-major 3×3
// layout (index 3·col + row), with signs: d_0 = I, d_1..3 = [e_1..3]×.
struct BasisEntry {
  int index;
  double sign;
};
const std::vector<BasisEntry>& basis_entries(int b) {
  static const std::vector<BasisEntry> entries[4] = {
      {{0, 1.0}, {4, 1.0}, {8, 1.0}},  // I
      {{5, 1.0}, {7, -1.0}},           // [e_x]×: (2,1) = +1, (1,2) = −1
      {{6, 1.0}, {2, -1.0}},           // [e_y]×: (0,2) = +1, (2,0) = −1
      {{1, 1.0}, {3, -1.0}}};          // [e_z]×: (1,0) = +1, (0,1) = −1
  return entries[b];
}
constexpr double kBasisNorm[4] = {3.0, 2.0, 2.0, 2.0};  // ‖d_b‖²_F

// Eq. 11's terms for one neighbour pair (k, j) with weight w = γ·a_kj, in
// clusters a and b: 2w·diag(3,2,2,2)·(Q_k − Q_j) in L_QQ; 2w⟨s_a − s_b, q_k − q_j⟩
// as −Sᵀ Dᵀ u entries of D; w‖s_a − s_b‖² in N.
void add_moving_frame_pair(Index qk, Index qj, Index a, Index b, double w, Triplets* tl, Triplets* td,
                           Triplets* tn) {
  for (int c = 0; c < 4; ++c) {
    const double v = 2.0 * w * kBasisNorm[c];
    tl->emplace_back(qk + c, qk + c, v);
    tl->emplace_back(qj + c, qj + c, v);
    tl->emplace_back(qk + c, qj + c, -v);
    tl->emplace_back(qj + c, qk + c, -v);
  }
  if (a == b) return;
  for (int c = 0; c < 4; ++c)
    for (const BasisEntry& be : basis_entries(c)) {
      const double v = 2.0 * w * be.sign;
      td->emplace_back(qk + c, 9 * a + be.index, -v);
      td->emplace_back(qk + c, 9 * b + be.index, v);
      td->emplace_back(qj + c, 9 * a + be.index, v);
      td->emplace_back(qj + c, 9 * b + be.index, -v);
    }
  for (int e = 0; e < 9; ++e) {
    tn->emplace_back(9 * a + e, 9 * a + e, 2.0 * w);
    tn->emplace_back(9 * b + e, 9 * b + e, 2.0 * w);
    tn->emplace_back(9 * a + e, 9 * b + e, -2.0 * w);
    tn->emplace_back(9 * b + e, 9 * a + e, -2.0 * w);
  }
}

// The triplets of the system: the scalar cotangent Laplacian (n × n, for
// L_VV = Lap ⊗ I₃), L (nu × nu), D (nu × 9d) and N (9d × 9d).
struct ArapTriplets {
  Triplets lap, l, d, n;
};

// One element's contributions, first summed on its own vertices (a
// spokes-and-rims element has about 7, a tet 4) and only then turned into
// triplets. The vectors are scratch reused from element to element.
struct ElementSums {
  Eigen::Matrix4d Lqq;  // L_QQ block (with the regulariser)
  Eigen::Matrix3d Nk;   // Σ c e eᵀ: ½Σc‖s e‖² = ½ Σ_rows s_row·Nk·s_rowᵀ
  Eigen::Matrix<double, 4, 9> dq;                // D_Q block
  std::vector<Index> local;                      // the element's vertices
  std::vector<Eigen::Matrix<double, 3, 4>> vq;   // L_VQ block per local vertex
  std::vector<Vec3> dv;                          // D_V: Σ ±c·e per local vertex

  size_t slot(Index v) {
    for (size_t t = 0; t < local.size(); ++t)
      if (local[t] == v) return t;
    local.push_back(v);
    vq.push_back(Eigen::Matrix<double, 3, 4>::Zero());
    dv.push_back(Vec3::Zero());
    return local.size() - 1;
  }
};

// Sums element k's edges (Eq. 9–10): ½c‖e′ − J·Q‖² and the linear term in
// s; appends the edges' scalar Laplacian triplets to *tlap.
void sum_element(const Vertices& V, const RotationElements& el, Index k, const EnergyParameters& params,
                 ElementSums* s, Triplets* tlap) {
  s->Lqq = regulariser(el.measure(k), params, el.is_surface, el.is_surface ? Vec3(row(el.normal, k)) : Vec3::Zero());
  s->Nk.setZero();
  s->dq.setZero();
  s->local.clear();
  s->vq.clear();
  s->dv.clear();
  for (Index e = el.offsets[k]; e < el.offsets[k + 1]; ++e) {
    const Index i = el.edge_i[e], j = el.edge_j[e];
    const double c = el.weight[e];
    const Vec3 ev = row(V, i) - row(V, j);
    const Eigen::Matrix<double, 3, 4> J = J_of(ev);
    tlap->emplace_back(i, i, c);
    tlap->emplace_back(j, j, c);
    tlap->emplace_back(i, j, -c);
    tlap->emplace_back(j, i, -c);
    const size_t si = s->slot(i), sj = s->slot(j);
    // ½c‖e′ − J·Q‖²: L[v′_i, Q_k] = −c·J, L[v′_j, Q_k] = +c·J.
    s->vq[si].noalias() -= c * J;
    s->vq[sj].noalias() += c * J;
    s->Lqq.noalias() += c * J.transpose() * J;
    s->Nk.noalias() += c * ev * ev.transpose();
    // Linear term: coefficient of s(rr, cc) is c·e_cc·(e′ − J·Q)_rr.
    s->dv[si] += c * ev;
    s->dv[sj] -= c * ev;
    for (int cc = 0; cc < 3; ++cc)
      for (int rr = 0; rr < 3; ++rr) s->dq.col(3 * cc + rr) -= c * ev(cc) * J.row(rr).transpose();
  }
}

// Turns element k's sums into triplets: Q unknowns from qk, its cluster's
// 9 columns of D and N from col0.
void emit_element(const ElementSums& s, Index qk, Index col0, ArapTriplets* t) {
  for (size_t i = 0; i < s.local.size(); ++i) {
    const Index v = s.local[i];
    for (int a = 0; a < 3; ++a) {
      for (int b = 0; b < 4; ++b) {
        const double x = s.vq[i](a, b);
        if (x == 0.0) continue;
        t->l.emplace_back(3 * v + a, qk + b, x);
        t->l.emplace_back(qk + b, 3 * v + a, x);
      }
    }
    for (int cc = 0; cc < 3; ++cc) {
      if (s.dv[i](cc) == 0.0) continue;
      for (int rr = 0; rr < 3; ++rr) t->d.emplace_back(3 * v + rr, col0 + 3 * cc + rr, s.dv[i](cc));
    }
  }
  for (int b = 0; b < 4; ++b)
    for (int c = 0; c < 9; ++c)
      if (s.dq(b, c) != 0.0) t->d.emplace_back(qk + b, col0 + c, s.dq(b, c));
  for (int a = 0; a < 4; ++a)
    for (int b = 0; b < 4; ++b) t->l.emplace_back(qk + a, qk + b, s.Lqq(a, b));
  // s(rr, cc) sits at col0 + 3cc + rr; the entries of one row rr couple.
  for (int rr = 0; rr < 3; ++rr)
    for (int c1 = 0; c1 < 3; ++c1)
      for (int c2 = 0; c2 < 3; ++c2)
        if (s.Nk(c1, c2) != 0.0) t->n.emplace_back(col0 + 3 * c1 + rr, col0 + 3 * c2 + rr, s.Nk(c1, c2));
}

// L_VV = Lap ⊗ I₃, appended to t->l; frees t->lap.
void add_vertex_block(Index n, ArapTriplets* t) {
  SparseMatrix<double> lap(n, n);
  lap.setFromTriplets(t->lap.begin(), t->lap.end());
  Triplets().swap(t->lap);
  t->l.reserve(t->l.size() + 3 * static_cast<size_t>(lap.nonZeros()));
  for (Index c = 0; c < n; ++c)
    for (SparseMatrix<double>::InnerIterator it(lap, c); it; ++it)
      for (int a = 0; a < 3; ++a) t->l.emplace_back(3 * it.row() + a, 3 * c + a, it.value());
}

void check_assembly_inputs(const RotationElements& el, const std::vector<int>& cluster, Index d,
                           const EnergyParameters& params) {
  std::string why;
  if (!params.is_valid(&why)) throw std::invalid_argument("EnergyParameters: " + why);
  const Index r = el.size();
  check_size("assemble_modified_arap: cluster labels", r, static_cast<Index>(cluster.size()));
  if (d < 1) throw std::invalid_argument("assemble_modified_arap: need at least one rotational cluster");
  for (Index k = 0; k < r; ++k) {
    if (cluster[k] < 0 || cluster[k] >= d) {
      throw std::invalid_argument(
          fmt::format("assemble_modified_arap: element {} has cluster {} outside [0, {})", k, cluster[k], d));
    }
  }
}

}  // namespace

ModifiedArapSystem assemble_modified_arap(const Vertices& V, const RotationElements& el,
                                          const std::vector<int>& cluster, Index d,
                                          const EnergyParameters& params) {
  check_assembly_inputs(el, cluster, d, params);
  const Index n = V.rows(), r = el.size();
  const Index nv = 3 * n, nu = nv + 4 * r;
  // Per element, then L_VV from the scalar cotangent Laplacian ⊗ I₃: far
  // fewer triplets than one set per edge, which was the precompute's memory
  // peak on 40k-vertex meshes.
  ArapTriplets t;
  t.lap.reserve(static_cast<size_t>(el.weight.size()) * 4);
  t.l.reserve(static_cast<size_t>(r) * (16 + 2 * 12 * 8));
  t.d.reserve(static_cast<size_t>(r) * (9 * 8 + 36));
  t.n.reserve(static_cast<size_t>(r) * 27);
  ElementSums sums;
  for (Index k = 0; k < r; ++k) {
    sum_element(V, el, k, params, &sums, &t.lap);
    emit_element(sums, nv + 4 * k, 9 * static_cast<Index>(cluster[k]), &t);
  }
  add_vertex_block(n, &t);
  if (params.gamma > 0.0) {
    for (const auto& [k, j] : element_neighbours(el)) {
      if (j >= r) {  // a surface subset made without select_elements: element ≠ vertex
        throw std::invalid_argument(fmt::format(
            "assemble_modified_arap: the surface elements' neighbour pair ({}, {}) is not below the {} elements "
            "(element k is vertex k; make subsets with select_elements, which records their vertices)",
            k, j, r));
      }
      const double w = params.gamma * 0.5 * (el.measure(k) + el.measure(j));
      add_moving_frame_pair(nv + 4 * k, nv + 4 * j, cluster[k], cluster[j], w, &t.l, &t.d, &t.n);
    }
  }
  ModifiedArapSystem sys;
  sys.q_separable = !(params.gamma > 0.0);
  sys.n = n;
  sys.r = r;
  sys.d = d;
  sys.L.resize(nu, nu);
  sys.L.setFromTriplets(t.l.begin(), t.l.end());
  sys.D.resize(nu, 9 * d);
  sys.D.setFromTriplets(t.d.begin(), t.d.end());
  sys.N.resize(9 * d, 9 * d);
  sys.N.setFromTriplets(t.n.begin(), t.n.end());
  return sys;
}

namespace {

// The inverses of L_QQ's 4×4 diagonal blocks (r of them) as a sparse nq × nq;
// throws when one is not positive definite.
SparseMatrix<double> inverse_element_blocks(const SparseMatrix<double>& LQQ, Index r) {
  Triplets tb;
  tb.reserve(static_cast<size_t>(r) * 16);
  for (Index k = 0; k < r; ++k) {
    Eigen::Matrix4d B = Eigen::Matrix4d::Zero();
    for (int b = 0; b < 4; ++b)
      for (SparseMatrix<double>::InnerIterator it(LQQ, 4 * k + b); it; ++it) B(it.row() - 4 * k, b) = it.value();
    // An element without edges (an unreferenced vertex's spokes-and-rims
    // element) has no energy at all: its q_k is free and untouched (block 0).
    if (B.isZero(0.0)) continue;
    const Eigen::LLT<Eigen::Matrix4d> llt(B);
    if (llt.info() != Eigen::Success || !(B.diagonal().minCoeff() > 0)) {
      throw std::invalid_argument(fmt::format(
          "eliminate_rotation_corrections: the 4×4 block of element {} is not positive definite (alpha = 0 and "
          "an element with too few edges?)",
          k));
    }
    const Eigen::Matrix4d Binv = llt.solve(Eigen::Matrix4d::Identity());
    for (int a = 0; a < 4; ++a)
      for (int b = 0; b < 4; ++b) tb.emplace_back(4 * k + a, 4 * k + b, Binv(a, b));
  }
  SparseMatrix<double> Binv(4 * r, 4 * r);
  Binv.setFromTriplets(tb.begin(), tb.end());
  return Binv;
}

// The rows (coordinates) of each element, sorted: the union of its 4
// columns of L_VQ, element k's in rows[start[k], start[k + 1]).
struct ElementRows {
  std::vector<Index> start, rows;
};
ElementRows element_rows(const SparseMatrix<double>& LVQ, Index r, Index nv) {
  ElementRows er;
  er.start.assign(static_cast<size_t>(r) + 1, 0);
  std::vector<Index> mark(static_cast<size_t>(nv), -1);
  for (Index k = 0; k < r; ++k) {
    for (int b = 0; b < 4; ++b)
      for (SparseMatrix<double>::InnerIterator it(LVQ, 4 * k + b); it; ++it)
        if (mark[static_cast<size_t>(it.row())] != k) {
          mark[static_cast<size_t>(it.row())] = k;
          er.rows.push_back(it.row());
        }
    std::sort(er.rows.begin() + er.start[static_cast<size_t>(k)], er.rows.end());
    er.start[static_cast<size_t>(k) + 1] = static_cast<Index>(er.rows.size());
  }
  return er;
}

// H's pattern, zero-valued: the union of L_VV's and the elements' coordinate
// cliques, each column's rows sorted.
SparseMatrix<double> eliminated_pattern(const SparseMatrix<double>& LVV, const ElementRows& er, Index r) {
  const Index nv = LVV.rows();
  const std::vector<Index>& start = er.start;
  const std::vector<Index>& rows = er.rows;
  // The elements of each coordinate (CSR), then each column's pattern.
  std::vector<Index> cstart(static_cast<size_t>(nv) + 1, 0), elems(rows.size());
  for (Index i : rows) ++cstart[static_cast<size_t>(i) + 1];
  for (Index j = 0; j < nv; ++j) cstart[static_cast<size_t>(j) + 1] += cstart[static_cast<size_t>(j)];
  {
    std::vector<Index> next(cstart.begin(), cstart.end() - 1);
    for (Index k = 0; k < r; ++k)
      for (Index t = start[static_cast<size_t>(k)]; t < start[static_cast<size_t>(k) + 1]; ++t)
        elems[static_cast<size_t>(next[static_cast<size_t>(rows[static_cast<size_t>(t)])]++)] = k;
  }
  std::vector<Index> mark(static_cast<size_t>(nv), -1);
  std::vector<int> outer(static_cast<size_t>(nv) + 1, 0);
  std::vector<int> inner;
  std::vector<Index> column;
  for (Index j = 0; j < nv; ++j) {
    column.clear();
    auto add = [&](Index i) {
      if (mark[static_cast<size_t>(i)] != j) {
        mark[static_cast<size_t>(i)] = j;
        column.push_back(i);
      }
    };
    for (SparseMatrix<double>::InnerIterator it(LVV, j); it; ++it) add(it.row());
    for (Index e = cstart[static_cast<size_t>(j)]; e < cstart[static_cast<size_t>(j) + 1]; ++e) {
      const Index k = elems[static_cast<size_t>(e)];
      for (Index t = start[static_cast<size_t>(k)]; t < start[static_cast<size_t>(k) + 1]; ++t)
        add(rows[static_cast<size_t>(t)]);
    }
    std::sort(column.begin(), column.end());
    for (Index i : column) inner.push_back(static_cast<int>(i));
    outer[static_cast<size_t>(j) + 1] = static_cast<int>(inner.size());
  }
  std::vector<Index>().swap(elems);
  std::vector<Index>().swap(cstart);
  SparseMatrix<double> H(nv, nv);
  H.resizeNonZeros(static_cast<Index>(inner.size()));
  std::copy(outer.begin(), outer.end(), H.outerIndexPtr());
  std::copy(inner.begin(), inner.end(), H.innerIndexPtr());
  std::vector<int>().swap(inner);
  std::fill(H.valuePtr(), H.valuePtr() + H.nonZeros(), 0.0);
  return H;
}

// H = L_VV − Σ_k L_Vk·B_k⁻¹·L_kV, element by element into H's final pattern
// (the union of the elements' coordinate cliques and L_VV's): one nv × nv
// matrix in memory, where a general sparse product L_VQ·B⁻¹·L_QV (and its
// symmetrisation) held four to six of them — on a 160k-vertex surface each
// is about 350 MB, and that product was the precompute's assembly peak.
// LVQ_Binv = L_VQ·B⁻¹ (nv × nq); its column 4k + b holds element k's rows.
// Each element's block W·L_kVᵀ is symmetrised before it is added, and every
// entry (i, j) and (j, i) sums the same terms in the same order, so H is
// exactly symmetric.
SparseMatrix<double> eliminated_hessian(const SparseMatrix<double>& LVV, const SparseMatrix<double>& LVQ,
                                        const SparseMatrix<double>& LVQ_Binv, Index r) {
  const Index nv = LVV.rows();
  const ElementRows er = element_rows(LVQ, r, nv);
  const std::vector<Index>& start = er.start;
  const std::vector<Index>& rows = er.rows;
  SparseMatrix<double> H = eliminated_pattern(LVV, er, r);
  // (i, j) in H: column j's rows are sorted.
  auto slot = [&](Index i, Index j) -> double& {
    const int* begin = H.innerIndexPtr() + H.outerIndexPtr()[j];
    const int* end = H.innerIndexPtr() + H.outerIndexPtr()[j + 1];
    return H.valuePtr()[std::lower_bound(begin, end, static_cast<int>(i)) - H.innerIndexPtr()];
  };
  for (Index j = 0; j < nv; ++j)
    for (SparseMatrix<double>::InnerIterator it(LVV, j); it; ++it) slot(it.row(), j) = it.value();
  // Element by element: W = rows of L_VQ·B⁻¹ (m × 4), V = rows of L_VQ, block = W·Vᵀ.
  Eigen::MatrixXd W, V, block;
  for (Index k = 0; k < r; ++k) {
    const Index s0 = start[static_cast<size_t>(k)], m = start[static_cast<size_t>(k) + 1] - s0;
    if (m == 0) continue;
    W.setZero(m, 4);
    V.setZero(m, 4);
    auto local = [&](Index i) {
      return std::lower_bound(rows.begin() + s0, rows.begin() + s0 + m, i) - (rows.begin() + s0);
    };
    for (int b = 0; b < 4; ++b) {
      for (SparseMatrix<double>::InnerIterator it(LVQ_Binv, 4 * k + b); it; ++it) W(local(it.row()), b) = it.value();
      for (SparseMatrix<double>::InnerIterator it(LVQ, 4 * k + b); it; ++it) V(local(it.row()), b) = it.value();
    }
    block.noalias() = W * V.transpose();
    for (Index c = 0; c < m; ++c)
      for (Index a = 0; a <= c; ++a) {
        const double x = 0.5 * (block(a, c) + block(c, a));
        const Index i = rows[static_cast<size_t>(s0 + a)], j = rows[static_cast<size_t>(s0 + c)];
        slot(i, j) -= x;
        if (i != j) slot(j, i) -= x;
      }
  }
  H.prune(1e-300);
  return H;
}

}  // namespace

EliminatedArapSystem eliminate_rotation_corrections(const ModifiedArapSystem& sys) {
  if (!sys.q_separable) {
    throw std::invalid_argument(
        "eliminate_rotation_corrections: L_QQ couples neighbouring elements (gamma > 0), so Q cannot be "
        "eliminated element by element; keep Q in the factored system");
  }
  const Index nv = 3 * sys.n, nq = 4 * sys.r;
  const SparseMatrix<double> LVQ = sys.L.block(0, nv, nv, nq);
  const SparseMatrix<double> Binv = inverse_element_blocks(sys.L.bottomRightCorner(nq, nq), sys.r);
  const SparseMatrix<double> DV = sys.D.topRows(nv);
  const SparseMatrix<double> DQ = sys.D.bottomRows(nq);
  const SparseMatrix<double> LVQ_Binv = detail::parallel_product(LVQ, Binv);
  EliminatedArapSystem out;
  out.H = eliminated_hessian(SparseMatrix<double>(sys.L.topLeftCorner(nv, nv)), LVQ, LVQ_Binv, sys.r);
  out.Ds = (DV - detail::parallel_product(LVQ_Binv, DQ)).pruned(1e-300);
  out.DV = DV;
  out.K = detail::parallel_product(SparseMatrix<double>(DQ.transpose()),
                                            detail::parallel_product(Binv, DQ))
              .pruned(1e-300);
  return out;
}

const char* to_string(ClusterRotationFit fit) {
  return fit == ClusterRotationFit::Exact ? "exact" : "paper";
}

double modified_arap_energy(const Vertices& V, const RotationElements& el, const std::vector<int>& cluster,
                            const EnergyParameters& params, const Vertices& Vp, const Eigen::VectorXd& Q,
                            const Eigen::VectorXd& S) {
  double energy = 0.0;
  for (Index k = 0; k < el.size(); ++k) {
    const Eigen::Map<const Eigen::Matrix3d> s(S.data() + 9 * cluster[k]);
    const Eigen::Vector4d q = Q.segment<4>(4 * k);
    Eigen::Matrix3d qm;
    qm << q(0), -q(3), q(2), q(3), q(0), -q(1), -q(2), q(1), q(0);  // Eq. 9
    for (Index e = el.offsets[k]; e < el.offsets[k + 1]; ++e) {
      const Index i = el.edge_i[e], j = el.edge_j[e];
      const Vec3 ev = row(V, i) - row(V, j), epv = row(Vp, i) - row(Vp, j);
      energy += 0.5 * el.weight[e] * (epv - (s + qm) * ev).squaredNorm();
    }
    energy += params.alpha * el.measure(k) * qm.squaredNorm();
    if (el.is_surface) energy += params.beta * el.measure(k) * (qm * Vec3(row(el.normal, k))).squaredNorm();
  }
  if (params.gamma > 0.0) {
    auto frame = [&](Index k) {  // s_{i_k} + q_k
      const Eigen::Vector4d q = Q.segment<4>(4 * k);
      Eigen::Matrix3d qm;
      qm << q(0), -q(3), q(2), q(3), q(0), -q(1), -q(2), q(1), q(0);
      return Eigen::Matrix3d(Eigen::Map<const Eigen::Matrix3d>(S.data() + 9 * cluster[k]) + qm);
    };
    for (const auto& [k, j] : element_neighbours(el))
      energy += params.gamma * 0.5 * (el.measure(k) + el.measure(j)) * (frame(k) - frame(j)).squaredNorm();
  }
  return energy;
}

double arap_energy(const Vertices& V, const RotationElements& el, const Vertices& Vp) {
  check_size("arap_energy: deformed vertex count", V.rows(), Vp.rows());
  double energy = 0.0;
  for (Index k = 0; k < el.size(); ++k) {
    Eigen::Matrix3d G = Eigen::Matrix3d::Zero();
    for (Index e = el.offsets[k]; e < el.offsets[k + 1]; ++e) {
      const Vec3 ev = row(V, el.edge_i[e]) - row(V, el.edge_j[e]);
      const Vec3 epv = row(Vp, el.edge_i[e]) - row(Vp, el.edge_j[e]);
      G.noalias() += el.weight[e] * epv * ev.transpose();
    }
    const Eigen::Matrix3d R = fit_rotation(G);
    for (Index e = el.offsets[k]; e < el.offsets[k + 1]; ++e) {
      const Vec3 ev = row(V, el.edge_i[e]) - row(V, el.edge_j[e]);
      const Vec3 epv = row(Vp, el.edge_i[e]) - row(Vp, el.edge_j[e]);
      energy += 0.5 * el.weight[e] * (epv - R * ev).squaredNorm();
    }
  }
  return energy;
}

}  // namespace qpreduce::deform
