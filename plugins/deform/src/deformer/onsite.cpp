// Deformer::set_handles, the on-site step (paper Section 3.2, "OP"): the
// constraint rows of a handle set in the subspace, A_r = AᵀB, handed to the
// engine's Alternation (Phase 1 and the fused rounds); free Rigid patches are
// tied to their cluster's rotation.
#include "qpreduce/deform/deformer/deformer.h"

#include "handle_checks.h"
#include "state.h"

#include <Eigen/Cholesky>
#include <Eigen/QR>
#include <Eigen/OrderingMethods>
#include <Eigen/SparseQR>
#include <fmt/format.h>

#include <cmath>

#include <algorithm>
#include <utility>

namespace qpreduce::deform {
namespace {

using detail::Model;
using detail::OnSite;
using detail::RowMatrixD;
using detail::Triplets;

// The constraint matrix A (n_u × cols, as triplets over control rows) of a
// handle set, in the order of the right-hand side b: 3 rows per point
// handle, 12 per Fixed patch, 12 per prescribed patch, then 9 per tie.
struct ConstraintLayout {
  Triplets a;
  Index cols = 0;
  std::vector<Index> tied;  // free Rigid patches
  Index tie_row0 = 0;       // their first row
};

// Point handles: the weighted point Σ w_i v_i, one column per axis.
void add_point_rows(const Model& model, const Handles& handles, ConstraintLayout* out) {
  for (const PointHandle& ph : handles.points) {
    for (size_t i = 0; i < ph.vertices.size(); ++i) {
      const double w = ph.weights.empty() ? 1.0 : ph.weights[i];
      for (int a = 0; a < 3; ++a) model.control_row(ph.vertices[i], a, w, out->cols + a, &out->a);
    }
    out->cols += 3;
  }
}

// Fixed and prescribed patches: their 12 transform entries; then the free
// Rigid patches: t_s = s_c (rows 3a + c of t_s, row-major).
void add_patch_rows(const Model& model, const Handles& handles, ConstraintLayout* out) {
  auto add = [&](Index p, int entries) {
    for (int c = 0; c < entries; ++c) out->a.emplace_back(model.patch_base + 12 * p + c, out->cols + c, 1.0);
    out->cols += entries;
  };
  for (Index p : model.fixed_patches) add(p, 12);
  for (Index p : handles.patches) add(p, 12);
  out->tie_row0 = out->cols;
  for (Index p = 0; p < model.s; ++p) {
    if (model.patch_types[p] != PatchType::Rigid ||
        std::find(handles.patches.begin(), handles.patches.end(), p) != handles.patches.end()) {
      continue;
    }
    out->tied.push_back(p);
    add(p, 9);
  }
}

// A_r = AᵀB (cols × p) row by row from rows of B kept row-major: a free
// vertex's control row r = 3i + a is row 3·free_vertices[i] + a of the float
// reconstruction basis P·B, a patch unknown's is in patch_rows (AᵀB on the
// column-major subspace would touch cols·p scattered cache lines); repeated
// entries simply add up.
RowMatrixD reduced_constraints(const Model& model, const ConstraintLayout& layout) {
  RowMatrixD Ar = RowMatrixD::Zero(layout.cols, model.nx + 9 * model.d);
  for (const auto& e : layout.a) {
    const Index r = e.row();
    if (r < model.patch_base) {
      const Index v = model.free_vertices[static_cast<size_t>(r / 3)];
      model.add_basis_row(3 * v + r % 3, e.value(), Ar.row(e.col()));
    } else {
      Ar.row(e.col()) += e.value() * model.patch_rows.row(r - model.patch_base);
    }
  }
  return Ar;
}

// One Alternation::setup on constraint rows of B = [N UD] (A_r, cols × p):
// A_z its first nx columns, A_y the 9d others.
ConstraintSummary setup_rows(const Model& model, const RowMatrixD& rows, const AlternationSetup& setup,
                             OnSite* onsite) {
  return onsite->alternation.setup(model.solver, rows.leftCols(model.nx), rows.rightCols(9 * model.d),
                                   *model.projection, setup);
}

// T (cols × 9d) of AlternationSetup::follow_y: row 3a + c of tie i follows
// s_c(a, c) of its patch's cluster k, entry 9k + 3c + a of y (empty without ties).
SparseMatrix<double> tie_rows(const Model& model, const ConstraintLayout& layout) {
  SparseMatrix<double> T;
  if (layout.tied.empty()) return T;
  Triplets t;
  for (size_t i = 0; i < layout.tied.size(); ++i) {
    const Index k = model.rigid_cluster_of_patch[layout.tied[i]];
    for (int a = 0; a < 3; ++a)
      for (int c = 0; c < 3; ++c)
        t.emplace_back(layout.tie_row0 + 9 * static_cast<Index>(i) + 3 * a + c, 9 * k + 3 * c + a, 1.0);
  }
  T.resize(layout.cols, 9 * model.d);
  T.setFromTriplets(t.begin(), t.end());
  return T;
}

// The handle set's rows in the full space, A (control rows × cols), and
// their rank by a sparse QR (COLAMD), pivots above 10⁻¹⁰ of the largest
// column norm. A row that is an exact combination of others (a vertex held
// twice, a group over handled vertices) leaves a pivot of round-off size;
// rows of distinct vertices are orthogonal, so the factorization stays as
// sparse as A even for thousands of handles. `independent`: `rank` columns
// of A that span the others (ascending). Formed once per set, and only for
// sets the subspace solved in the least-squares sense.
struct FullSpaceRows {
  SparseMatrix<double> A;
  Index rank = 0;
  std::vector<Index> independent;
};
FullSpaceRows full_space_rows(const ConstraintLayout& layout) {
  FullSpaceRows out;
  if (layout.cols == 0) return out;
  Index rows = 0;
  for (const auto& e : layout.a) rows = std::max<Index>(rows, e.row() + 1);
  out.A.resize(rows, layout.cols);
  out.A.setFromTriplets(layout.a.begin(), layout.a.end());  // repeated entries add up, as in reduced_constraints
  out.A.makeCompressed();
  double top = 0.0;
  for (Index j = 0; j < out.A.cols(); ++j) top = std::max(top, out.A.col(j).norm());
  if (!(top > 0.0)) return out;
  Eigen::SparseQR<SparseMatrix<double>, Eigen::COLAMDOrdering<int>> qr;
  qr.setPivotThreshold(1e-10 * top);
  qr.compute(out.A);
  if (qr.info() != Eigen::Success) return out;
  out.rank = qr.rank();
  for (Index i = 0; i < out.rank; ++i) out.independent.push_back(qr.colsPermutation().indices()(i));
  std::sort(out.independent.begin(), out.independent.end());
  return out;
}

// A dependent set (its rank below its row count, the same in the full space
// and the subspace): A = A_I·E with A_I the independent columns, so AᵀX = b
// holds in the least-squares sense exactly when A_IᵀX = c with c = P·b,
// P = (E·Eᵀ)⁻¹·E (rank × cols; for a vertex held twice, the mean of its two
// targets). Returns P.
Matrix<double> target_projection(const SparseMatrix<double>& A, const std::vector<Index>& independent) {
  const Index r = static_cast<Index>(independent.size());
  SparseMatrix<double> select(A.cols(), r);  // A_I = A·select, sparse as A
  for (Index i = 0; i < r; ++i) select.insert(independent[static_cast<size_t>(i)], i) = 1.0;
  const SparseMatrix<double> AI = A * select;
  const SparseMatrix<double> AIt = AI.transpose();
  const Matrix<double> G = Matrix<double>(AIt * AI);                 // r × r, SPD (independent columns)
  const Matrix<double> E = G.ldlt().solve(Matrix<double>(AIt * A));  // r × cols
  return (E * E.transpose()).ldlt().solve(E);
}

// Why a hard set's exact answer cannot be trusted (DeformerOptions::
// soften_unreachable_handles), or "": its rank in the subspace (of A_z) is
// below its rank in the full space, or its condition there (over the rank
// it has, for a dependent set too) is above kSoftCondition (the float
// basis's round-off, 6·10⁻⁸ relative, times the condition then passes 1 %).
constexpr double kSoftCondition = 1e5;

std::string unreachable_reason(const FullSpaceRows& full, const ConstraintSummary& cs) {
  if (cs.status == Status::ConstraintsLeastSquares) {
    const Index full_rank = full.rank;
    if (cs.rank >= full_rank && cs.condition > kSoftCondition) {  // dependent, and ill-conditioned in the subspace
      return fmt::format(
          "their {} constraint rows (rank {}, as in the full space) have condition {:.3g} in the subspace, above "
          "{:.0e}: the float basis's round-off (6·10⁻⁸) alone can move the least-squares answer by more than 1 %",
          cs.m, cs.rank, cs.condition, kSoftCondition);
    }
    if (cs.rank >= full_rank) return {};  // merely dependent rows: the subspace meets what the full space can
    return fmt::format(
        "their {} constraint rows have rank {} in the full space but {} in the subspace (more point handles than the "
        "proxies can follow)",
        cs.m, full_rank, cs.rank);
  }
  if (cs.status == Status::Success && cs.condition > kSoftCondition) {
    return fmt::format(
        "their {} constraint rows have condition {:.3g} in the subspace, above {:.0e}: the float basis's round-off "
        "(6·10⁻⁸) alone can move the exact answer by more than 1 %",
        cs.m, cs.condition, kSoftCondition);
  }
  return {};
}

}  // namespace

namespace detail {

std::string plain_reason(const Model& model, bool exact_rotation_fit, bool tied) {
  // The energy terms assume no ties and the exact Phase 2 input; a custom
  // projection may not define its energy on Phase 2 outputs (quadratic_term
  // NaN: InputProjection).
  if (!exact_rotation_fit) return "the model uses the paper's Eq. 19 rotation step";
  if (tied) return "this handle set ties a free Rigid patch to its cluster";
  if (!std::isfinite(model.projection->quadratic_term(Vector<double>::Zero(9 * model.d))))
    return "the model's projection defines no quadratic_term";
  return {};
}

}  // namespace detail

// A dependent set that the subspace meets as well as the full space does (a
// vertex held twice, a group over held vertices; no ties, hard constraints):
// its independent rows, solved exactly, with the targets projected onto them
// each frame (target_projection). The rounds then step on E′ as for any
// exact set, where the least-squares form runs uncorrected rounds that need
// not converge. Returns false (and changes nothing) when it does not apply.
bool reduce_dependent_rows(const Model& model, const ConstraintLayout& layout, const FullSpaceRows& full,
                           const RowMatrixD& Ar, const AlternationSetup& setup, OnSite* onsite,
                           ConstraintSummary* cs) {
  if (cs->status != Status::ConstraintsLeastSquares || setup.constraints.soft || !layout.tied.empty()) return false;
  const std::vector<Index>& independent = full.independent;
  if (full.rank == 0 || full.rank >= layout.cols || cs->rank < full.rank) return false;
  RowMatrixD ArI(full.rank, Ar.cols());
  for (Index i = 0; i < full.rank; ++i) ArI.row(i) = Ar.row(independent[static_cast<size_t>(i)]);
  const ConstraintSummary reduced = setup_rows(model, ArI, setup, onsite);
  if (reduced.status != Status::Success) {  // back to the least-squares form
    setup_rows(model, Ar, setup, onsite);
    return false;
  }
  onsite->target_projection = target_projection(full.A, independent);
  ConstraintSummary out = reduced;
  out.status = Status::ConstraintsLeastSquares;
  out.m = layout.cols;
  out.message = fmt::format(
      "{} hard constraints have rank {} (dependent rows: a vertex held twice, or a group over held vertices): "
      "they hold in the least-squares sense, their targets projected onto {} independent rows each frame, which "
      "hold exactly (condition {:.3g})",
      layout.cols, full.rank, full.rank, reduced.condition);
  *cs = out;
  return true;
}

// An exact set whose answer cannot be trusted (`why`, from
// unreachable_reason; empty: nothing to do) solved as soft constraints
// (Eq. 18) instead: bounded where the exact fit is not. Returns true with
// *cs the softened summary; false (the exact form kept, *cs as it was) when
// the soft set fails too or `why` is empty.
bool soften_unreachable(const Model& model, const RowMatrixD& Ar, const AlternationSetup& setup,
                        const std::string& why, OnSite* onsite, ConstraintSummary* cs) {
  if (why.empty()) return false;
  AlternationSetup soft = setup;
  soft.constraints.soft = true;
  // More rows than the subspace has coordinates: the soft term
  // δ‖A_r·x − b‖² is δ‖R·x − Qᵀb‖² plus a constant (A_r = Q·R, thin), so
  // the set is solved on the p rows of R with the targets projected by Qᵀ
  // each frame (OnSite::target_projection): the same minimiser, and few
  // enough rows for the energy terms (the rounds then step on E′).
  RowMatrixD Rsoft;
  if (Ar.rows() > Ar.cols()) {
    const Eigen::HouseholderQR<Matrix<double>> qr(Ar);
    const Index p = Ar.cols();
    Rsoft = qr.matrixQR().topRows(p).triangularView<Eigen::Upper>();
    onsite->target_projection = (qr.householderQ() * Matrix<double>::Identity(Ar.rows(), p)).transpose();
  }
  const RowMatrixD& As = Rsoft.size() > 0 ? Rsoft : Ar;
  ConstraintSummary ss = setup_rows(model, As, soft, onsite);
  if (!ss.ok()) {  // keep the exact form, as before
    onsite->target_projection.resize(0, 0);
    *cs = setup_rows(model, Ar, setup, onsite);
    return false;
  }
  ss.status = Status::ConstraintsLeastSquares;
  ss.beyond_subspace = true;
  ss.message = fmt::format(
      "the subspace cannot meet these handles reliably: {}; they are met as soft constraints (Eq. 18, δ = "
      "{:.3g}), the closest fit at bounded energy",
      why, setup.constraints.delta);
  *cs = ss;
  return true;
}

ConstraintSummary Deformer::set_handles(const Handles& handles, const ConstraintOptions& options) {
  State& st = *state_;
  if (!st.ready) throw std::invalid_argument("Deformer::set_handles: call precompute first");
  const Model& model = st.model;
  if (!model.whole_basis()) {
    throw std::invalid_argument(fmt::format(
        "Deformer::set_handles: this deformer holds rows [{}, {}) of the {}-row reconstruction basis (a part of a "
        "distributed precompute); save it with the other parts' rows and load the cache",
        model.basis_first, model.basis_first + model.basis_count(), 3 * model.n));
  }
  OnSite& onsite = st.onsite;
  detail::check_handles(handles, model.n, model.patch_types);
  ConstraintLayout layout;
  add_point_rows(model, handles, &layout);
  add_patch_rows(model, handles, &layout);
  const RowMatrixD Ar = reduced_constraints(model, layout);
  // Phase 1, its energy terms (unless the rounds must run plain), the
  // proximal weights and the fused rounds, for G_z = M_N, G_y = M_U; a tie's
  // rows follow its cluster's rotation.
  AlternationSetup setup;
  setup.constraints = options;
  setup.follow_y = tie_rows(model, layout);
  onsite.plain_reason = detail::plain_reason(
      model, st.inputs.options.rotation_fit == ClusterRotationFit::Exact, !layout.tied.empty());
  setup.energy_terms = onsite.plain_reason.empty();
  setup.precision = st.fused_precision();
  ConstraintSummary cs = setup_rows(model, Ar, setup, &onsite);
  onsite.target_projection.resize(0, 0);
  const FullSpaceRows full =
      cs.status == Status::ConstraintsLeastSquares ? full_space_rows(layout) : FullSpaceRows{};
  // (Not with ties: a free Rigid patch's tie to its cluster must hold exactly.)
  const bool softened = st.settings.soften_unreachable_handles && !options.soft && layout.tied.empty() &&
                        soften_unreachable(model, Ar, setup, unreachable_reason(full, cs), &onsite, &cs);
  const bool reduced = !softened && reduce_dependent_rows(model, layout, full, Ar, setup, &onsite, &cs);
  // A least-squares set neither softened nor reduced to its independent rows:
  // is it the subspace's doing (a lower rank than in the full space)?
  if (cs.status == Status::ConstraintsLeastSquares && !softened && !reduced)
    cs.beyond_subspace = cs.rank < full.rank;
  onsite.tied_patches = std::move(layout.tied);
  // A set solved exactly (a softened one too: it has at most as many rows
  // as the subspace has coordinates, compressed above) got Phase 1's energy
  // terms, which the rounds need to step on E′ with point handles, whose
  // rows involve the cluster rotations (docs/engine.md, "Constraints on y").
  if (onsite.plain_reason.empty() && !onsite.alternation.energy_terms())
    onsite.plain_reason = "this handle set's constraints were not solved exactly";
  onsite.tie_row0 = layout.tie_row0;
  onsite.handles = handles;
  onsite.rows = layout.cols;
  onsite.warm = false;
  st.work.b_targets.setZero(layout.cols);
  st.work.b.setZero(onsite.target_projection.size() > 0 ? onsite.target_projection.rows() : layout.cols);
  return cs;
}

}  // namespace qpreduce::deform
