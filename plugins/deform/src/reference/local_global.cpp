// Local-global (Sorkine–Alexa) ARAP in full space, classic or modified
// energy, one cached factorization per handle set (reference.h).
// The solve's pieces: local_global_rounds.h, local_global_solve.cpp.
#include "local_global_rounds.h"

#include <fmt/format.h>

namespace qpreduce::deform {

struct LocalGlobalArap::State : detail::LocalGlobalState {};

namespace {

using detail::LocalGlobalState;
using detail::PreparedModel;
using detail::Triplets;

// ---- set_handles

// Pinned control rows: the 12 parameters of Fixed and prescribed patches,
// and the coordinates of free vertices held by single-vertex handles. The
// other point handles become general rows (3 each, over the whole control
// layer, in *tg; their handles in st.general_handles).
std::vector<char> pin_rows(LocalGlobalState& st, const Handles& handles, Triplets* tg) {
  std::vector<char> pinned(static_cast<size_t>(st.nu), 0);
  for (Index p = 0; p < st.s; ++p) {
    const bool held = st.m.patch_types[p] == PatchType::Fixed ||
                      std::find(handles.patches.begin(), handles.patches.end(), p) != handles.patches.end();
    if (held)
      for (int c = 0; c < 12; ++c) pinned[st.nu - 12 * st.s + 12 * p + c] = 1;
  }
  st.general_handles.clear();
  for (size_t h = 0; h < handles.points.size(); ++h) {
    const PointHandle& ph = handles.points[h];
    const bool single = ph.vertices.size() == 1 && (ph.weights.empty() || ph.weights[0] == 1.0);
    if (single) {
      const Index v = ph.vertices[0];
      const int p = st.m.patch_of_vertex[v];
      if (p < 0) {
        for (int a = 0; a < 3; ++a) pinned[st.control_of_free[v] + a] = 1;
        continue;
      }
      if (pinned[st.nu - 12 * st.s + 12 * p]) continue;  // held by its patch (targets compared in solve)
    }
    const Index row = 3 * static_cast<Index>(st.general_handles.size());
    for (size_t i = 0; i < ph.vertices.size(); ++i)
      for (int a = 0; a < 3; ++a) st.control_row(ph.vertices[i], a, ph.weights.empty() ? 1.0 : ph.weights[i], row + a, tg);
    st.general_handles.push_back(h);
  }
  return pinned;
}

// Numbers the free rows (st.free_index) and the pinned ones (st.pinned_rows,
// their index in *pinned_index); returns the free count.
Index number_rows(LocalGlobalState& st, const std::vector<char>& pinned, std::vector<Index>* pinned_index) {
  st.free_index.assign(static_cast<size_t>(st.nu), -1);
  pinned_index->assign(static_cast<size_t>(st.nu), -1);
  st.pinned_rows.clear();
  Index nf = 0;
  for (Index r = 0; r < st.nu; ++r) {
    if (pinned[r]) {
      (*pinned_index)[r] = static_cast<Index>(st.pinned_rows.size());
      st.pinned_rows.push_back(r);
    } else {
      st.free_index[r] = nf++;
    }
  }
  return nf;
}

// Splits Hu and the general rows into free and pinned columns: returns K
// (free × free) and sets Hfp, Af and Ap.
SparseMatrix<double> split_columns(LocalGlobalState& st, const Triplets& tg, const std::vector<Index>& pinned_index,
                                   Index nf) {
  const Index np = static_cast<Index>(st.pinned_rows.size());
  const Index mg = 3 * static_cast<Index>(st.general_handles.size());
  Triplets tff, tfp, taf, tap;
  for (Index c = 0; c < st.nu; ++c)
    for (SparseMatrix<double>::InnerIterator it(st.Hu, c); it; ++it) {
      const Index r = it.row();
      if (st.free_index[r] < 0) continue;
      if (st.free_index[c] >= 0) tff.emplace_back(st.free_index[r], st.free_index[c], it.value());
      else tfp.emplace_back(st.free_index[r], pinned_index[c], it.value());
    }
  for (const auto& t : tg) {
    if (st.free_index[t.row()] >= 0) taf.emplace_back(t.col(), st.free_index[t.row()], t.value());
    else tap.emplace_back(t.col(), pinned_index[t.row()], t.value());
  }
  SparseMatrix<double> K(nf, nf);
  K.setFromTriplets(tff.begin(), tff.end());
  st.Hfp.resize(nf, np);
  st.Hfp.setFromTriplets(tfp.begin(), tfp.end());
  st.Af.resize(mg, nf);
  st.Af.setFromTriplets(taf.begin(), taf.end());
  st.Ap.resize(mg, np);
  st.Ap.setFromTriplets(tap.begin(), tap.end());
  return K;
}

// K += ρAfᵀAf with ρ the scale of K's diagonal over that of AfᵀAf, so the
// augmentation neither dominates nor vanishes in rounding (the KKT answer
// does not depend on ρ).
void augment(LocalGlobalState& st, SparseMatrix<double>* K) {
  const SparseMatrix<double> AtA = SparseMatrix<double>(st.Af.transpose() * st.Af);
  const double kd = K->diagonal().cwiseAbs().mean(), ad = AtA.diagonal().cwiseAbs().maxCoeff();
  if (!(ad > 0)) throw std::invalid_argument("LocalGlobalArap: a weighted point handle has only zero weights");
  st.rho = kd / ad;
  *K += st.rho * AtA;
}

// G = (K + ρAfᵀAf)⁻¹Afᵀ and the Schur complement Af·G of the point rows.
// Throws std::invalid_argument when the weighted handles are dependent.
void factor_point_rows(LocalGlobalState& st) {
  st.G = Matrix<double>(st.Af.transpose());
  st.factor->solveInPlace(st.G, 64);
  const Eigen::MatrixXd schur = st.Af * st.G;
  st.schur.compute(schur);
  const double dmax = st.schur.vectorD().cwiseAbs().maxCoeff();
  if (st.schur.info() != Eigen::Success || !(st.schur.vectorD().minCoeff() > 1e-12 * dmax)) {
    throw std::invalid_argument(
        "LocalGlobalArap: the weighted point handles are linearly dependent (two handles constrain the same "
        "combination of vertices)");
  }
}

// ---- one factorization per axis when the global step allows it

// The global step of classic ARAP is H = L ⊗ I₃ (the same Laplacian for x, y
// and z), and pinning whole patches or vertices keeps that: K = K_s ⊗ I₃ on
// the free vertex coordinates, numbered x, y, z per free vertex. K_s is then
// factored once (n_f/3 × n_f/3) and a right-hand side of K is solved as three
// of K_s: a third of the unknowns, a ninth of the factor, and the axes solved
// together (three columns per triangular sweep instead of one).
class AxisSeparableFactorization final : public SparseFactorization {
 public:
  AxisSeparableFactorization(std::unique_ptr<SparseFactorization> inner, Index n)
      : inner_(std::move(inner)), n_(n) {}
  void analyzePattern(const SparseMatrix<double>& A) override { inner_->analyzePattern(A); }
  void factorize(const SparseMatrix<double>& A) override { inner_->factorize(A); }
  Eigen::ComputationInfo info() const override { return inner_->info(); }
  const std::string& message() const override { return inner_->message(); }
  Backend backend() const override { return inner_->backend(); }
  Index factorNonZeros() const override { return inner_->factorNonZeros(); }
  // B: 3n_s × c, rows x, y, z of each free vertex; solved as n_s × 3c.
  void solveInPlace(Matrix<double>& B, Index block_size) const override {
    const Index ns = n_, c = B.cols();
    Matrix<double> T(ns, 3 * c);
    for (Index j = 0; j < c; ++j)
      T.middleCols(3 * j, 3) = Eigen::Map<const Eigen::Matrix<double, 3, Eigen::Dynamic>>(B.col(j).data(), 3, ns).transpose();
    inner_->solveInPlace(T, std::max<Index>(3, 3 * block_size));
    for (Index j = 0; j < c; ++j)
      Eigen::Map<Eigen::Matrix<double, 3, Eigen::Dynamic>>(B.col(j).data(), 3, ns) = T.middleCols(3 * j, 3).transpose();
  }

 private:
  std::unique_ptr<SparseFactorization> inner_;
  Index n_;
};

// The per-axis factor. Backend::Auto: CHOLMOD's simplicial LDLᵀ, whose solve
// sweeps the factor once for a round's three right-hand sides (Eigen's
// SimplicialLDLT sweeps it three times; CHOLMOD's supernodal solve spends
// more on its per-supernode BLAS calls than on the arithmetic on meshes:
// docs/performance.md, "The per-axis solve"). Any other backend is taken
// as given.
std::unique_ptr<SparseFactorization> separable_factorization(Backend requested) {
  return requested == Backend::Auto ? make_cholmod_simplicial_factorization() : make_factorization(requested);
}

// K_s when K (free × free) is K_s ⊗ I₃ over free vertices numbered x, y, z
// (every free row a vertex coordinate, the three of a vertex free together,
// no entry between axes, the same value on all three); empty otherwise.
SparseMatrix<double> axis_block(const LocalGlobalState& st, const SparseMatrix<double>& K) {
  const Index nf = K.rows();
  SparseMatrix<double> none;
  if (nf % 3 != 0) return none;
  const Index vertex_rows = st.nu - 12 * st.s;
  for (Index r = 0; r < st.nu; ++r) {
    const Index f = st.free_index[r];
    if (f < 0) continue;
    if (r >= vertex_rows || f % 3 != r % 3 || st.free_index[r - r % 3] != f - r % 3) return none;
  }
  Triplets ts;
  ts.reserve(static_cast<size_t>(K.nonZeros() / 3));
  for (Index c = 0; c < nf; c += 3)
    for (SparseMatrix<double>::InnerIterator it(K, c); it; ++it)
      if (it.row() % 3 == 0) ts.emplace_back(it.row() / 3, c / 3, it.value());
  SparseMatrix<double> Ks(nf / 3, nf / 3);
  Ks.setFromTriplets(ts.begin(), ts.end());
  Index matched = 0;
  for (Index c = 0; c < nf; ++c)
    for (SparseMatrix<double>::InnerIterator it(K, c); it; ++it) {
      if (it.value() == 0.0) continue;
      if (it.row() % 3 != c % 3) return none;
      const double v = Ks.coeff(it.row() / 3, c / 3);
      if (std::abs(v - it.value()) > 1e-14 * std::abs(v)) return none;
      ++matched;
    }
  Index ks_nonzeros = 0;
  for (Index c = 0; c < Ks.outerSize(); ++c)
    for (SparseMatrix<double>::InnerIterator it(Ks, c); it; ++it) ks_nonzeros += it.value() != 0.0;
  if (matched != 3 * ks_nonzeros) return none;
  return Ks;
}

// The element–vertex pairs of LocalGlobalState: per element its distinct
// vertices and a_kv, then the pairs by vertex (a counting sort).
void element_vertex_pairs(LocalGlobalState* st) {
  const RotationElements& el = st->m.elements;
  const Index r = el.size();
  st->pair_offsets.assign(static_cast<size_t>(r + 1), 0);
  st->pair_vertex.clear();
  st->pair_element.clear();
  std::vector<Eigen::Vector3d> a;
  for (Index k = 0; k < r; ++k) {
    const Index first = static_cast<Index>(st->pair_vertex.size());
    auto add = [&](Index v, const Eigen::Vector3d& x) {
      for (Index p = first; p < static_cast<Index>(st->pair_vertex.size()); ++p)
        if (st->pair_vertex[p] == v) {
          a[p] += x;
          return;
        }
      st->pair_vertex.push_back(v);
      st->pair_element.push_back(k);
      a.push_back(x);
    };
    for (Index e = el.offsets[k]; e < el.offsets[k + 1]; ++e) {
      const Eigen::Vector3d ce = el.weight[e] * st->rest_edge.col(e);
      add(el.edge_i[e], ce);
      add(el.edge_j[e], -ce);
    }
    st->pair_offsets[k + 1] = static_cast<Index>(st->pair_vertex.size());
  }
  const Index pairs = static_cast<Index>(st->pair_vertex.size());
  st->pair_a.resize(3, pairs);
  for (Index p = 0; p < pairs; ++p) st->pair_a.col(p) = a[p];
  st->vertex_pair_offsets.assign(static_cast<size_t>(st->n + 1), 0);
  for (Index p = 0; p < pairs; ++p) ++st->vertex_pair_offsets[st->pair_vertex[p] + 1];
  for (Index v = 0; v < st->n; ++v) st->vertex_pair_offsets[v + 1] += st->vertex_pair_offsets[v];
  st->vertex_pairs.resize(static_cast<size_t>(pairs));
  std::vector<Index> next(st->vertex_pair_offsets.begin(), st->vertex_pair_offsets.end() - 1);
  for (Index p = 0; p < pairs; ++p) st->vertex_pairs[next[st->pair_vertex[p]]++] = p;
}

// The rest edges, the element–vertex pairs and the planar elements of the
// classic local step (LocalGlobalState).
void classic_local_data(LocalGlobalState* st) {
  const RotationElements& el = st->m.elements;
  const Index E = static_cast<Index>(el.weight.size()), r = el.size();
  st->rest_edge.resize(3, E);
  for (Index e = 0; e < E; ++e)
    st->rest_edge.col(e) = (st->m.V.row(el.edge_i[e]) - st->m.V.row(el.edge_j[e])).transpose();
  element_vertex_pairs(st);
  // Planar: every rest edge within 1e-12 of its length of the plane n⊥, so
  // that ‖G n‖ ≤ 1e-12·Σ|c|‖e′‖‖e‖ (fit_rotation_planar's precondition).
  st->plane_normal = Eigen::Matrix<double, 3, Eigen::Dynamic>::Zero(3, r);
  if (!el.is_surface || el.normal.rows() != r) return;
  for (Index k = 0; k < r; ++k) {
    const Eigen::Vector3d normal = el.normal.row(k).transpose();
    if (!(normal.norm() > 0.5) || el.offsets[k] == el.offsets[k + 1]) continue;
    const Eigen::Vector3d n = normal.normalized();
    bool planar = true;
    for (Index e = el.offsets[k]; e < el.offsets[k + 1] && planar; ++e)
      planar = std::abs(n.dot(st->rest_edge.col(e))) <= 1e-12 * st->rest_edge.col(e).norm();
    if (planar) st->plane_normal.col(k) = n;
  }
}

}  // namespace

LocalGlobalArap::LocalGlobalArap() : state_(std::make_unique<State>()) {}
LocalGlobalArap::~LocalGlobalArap() = default;
LocalGlobalArap::LocalGlobalArap(LocalGlobalArap&&) noexcept = default;
LocalGlobalArap& LocalGlobalArap::operator=(LocalGlobalArap&&) noexcept = default;

const RotationElements& LocalGlobalArap::elements() const { return state_->given_elements; }

void LocalGlobalArap::precompute(const DeformableMesh& model, const ReferenceOptions& options) {
  auto owned = std::make_unique<State>();
  State& st = *owned;
  st.options = options;
  st.units = normalization_of(model.V);
  st.m = detail::prepare_model(normalised(model, st.units), options);
  st.energy_unit = energy_unit(st.units, st.m.tet);
  st.given_elements = in_given_units(st.m.elements, st.units);
  st.frame_targets = detail::targets_model(st.m);
  st.given_targets = st.frame_targets;
  st.given_targets.V = model.V;
  st.n = st.m.V.rows();
  st.s = static_cast<Index>(st.m.patch_types.size());
  st.control_of_free.assign(static_cast<size_t>(st.n), -1);
  Index free_count = 0;
  for (Index v = 0; v < st.n; ++v)
    if (st.m.patch_of_vertex[v] < 0) st.control_of_free[v] = 3 * free_count++;
  st.nu = 3 * free_count + 12 * st.s;
  Triplets tp;
  for (Index v = 0; v < st.n; ++v)
    for (int a = 0; a < 3; ++a) st.control_row(v, a, 1.0, 3 * v + a, &tp);
  SparseMatrix<double> Pt(st.nu, 3 * st.n);  // control_row fills (control row, column) = Pᵀ
  Pt.setFromTriplets(tp.begin(), tp.end());
  st.P = Pt.transpose();

  SparseMatrix<double> H;
  if (options.energy == ReferenceEnergy::ClassicArap) {
    // H = Σ_k Σ_e c (ξ_i − ξ_j)(ξ_i − ξ_j)ᵀ ⊗ I₃.
    const RotationElements& el = st.m.elements;
    Triplets th;
    th.reserve(el.weight.size() * 12);
    for (size_t e = 0; e < el.weight.size(); ++e) {
      const Index i = el.edge_i[e], j = el.edge_j[e];
      const double c = el.weight[e];
      for (int a = 0; a < 3; ++a) {
        th.emplace_back(3 * i + a, 3 * i + a, c);
        th.emplace_back(3 * j + a, 3 * j + a, c);
        th.emplace_back(3 * i + a, 3 * j + a, -c);
        th.emplace_back(3 * j + a, 3 * i + a, -c);
      }
    }
    H.resize(3 * st.n, 3 * st.n);
    H.setFromTriplets(th.begin(), th.end());
    classic_local_data(&st);
  } else {
    const ModifiedArapSystem sys = assemble_modified_arap(st.m.V, st.m.elements, st.m.clusters, st.m.d, st.m.parameters);
    const EliminatedArapSystem elim = eliminate_rotation_corrections(sys);
    const Index nv = 3 * st.n, nq = 4 * sys.r;
    H = elim.H;
    st.Ds = elim.Ds;
    st.DV = elim.DV;
    st.D = sys.D;
    st.DQ = sys.D.bottomRows(nq);
    st.LQV = sys.L.block(nv, 0, nq, nv);
    st.LQQ.compute(SparseMatrix<double>(sys.L.bottomRightCorner(nq, nq)));
    if (st.LQQ.info() != Eigen::Success) {
      throw std::invalid_argument("LocalGlobalArap: the Q block of E' is not positive definite (alpha = 0?)");
    }
  }
  st.Hu = SparseMatrix<double>(Pt * H * st.P);
  state_ = std::move(owned);
}

HandleSetSummary LocalGlobalArap::set_handles(const Handles& handles) {
  const Timer timer;
  State& st = *state_;
  HandleSetSummary summary;
  if (st.n == 0) throw std::invalid_argument("LocalGlobalArap::set_handles: call precompute first");
  detail::check_handles(st.m, handles);
  detail::check_anchored(st.m, handles);
  st.has_handles = false;
  st.handles = handles;
  Triplets tg;  // general rows over the whole control layer
  const std::vector<char> pinned = pin_rows(st, handles, &tg);
  std::vector<Index> pinned_index;
  const Index nf = number_rows(st, pinned, &pinned_index);
  const Index np = static_cast<Index>(st.pinned_rows.size());
  const Index mg = 3 * static_cast<Index>(st.general_handles.size());
  SparseMatrix<double> K = split_columns(st, tg, pinned_index, nf);
  if (mg > 0) augment(st, &K);
  SparseMatrix<double> Ks = axis_block(st, K);
  st.free_vertex.clear();
  st.Ks = SparseMatrix<double>();
  if (Ks.rows() > 0) {
    K = SparseMatrix<double>();  // free it before the factorization
    st.factor = std::make_unique<AxisSeparableFactorization>(separable_factorization(st.options.backend), Ks.rows());
    st.factor->compute(Ks);
    // The Newton steps' products (Rounds::hessian_vector) on the free
    // vertices directly: K_ff = K_s ⊗ I₃ and the vertex of each free unit.
    st.free_vertex.assign(static_cast<size_t>(Ks.rows()), -1);
    for (Index v = 0; v < st.n; ++v) {
      const Index c = st.control_of_free[v];
      if (c >= 0 && st.free_index[c] >= 0) st.free_vertex[static_cast<size_t>(st.free_index[c] / 3)] = v;
    }
    st.Ks = std::move(Ks);
  } else {
    st.factor = make_factorization(st.options.backend);
    st.factor->compute(K);
  }
  summary.axis_separable = st.Ks.rows() > 0;
  summary.free_coordinates = nf;
  summary.pinned_coordinates = np;
  summary.point_rows = mg;
  if (st.factor->info() != Eigen::Success) {
    summary.status = Status::NumericalFailure;
    summary.message = "global step matrix: " + st.factor->message();
    summary.seconds = timer.seconds();
    return summary;
  }
  if (mg > 0) factor_point_rows(st);
  st.has_handles = true;
  summary.status = Status::Success;
  summary.message = fmt::format("{} free coordinates, {} pinned, {} weighted-point rows{}", nf, np, mg,
                                summary.axis_separable ? ", one factor for the three axes" : "");
  summary.seconds = timer.seconds();
  return summary;
}

ReferenceSummary LocalGlobalArap::solve(const HandleTargets& targets, ReferenceSolution* out, const Vertices& initial,
                                        const std::function<bool()>& cancel) {
  const State& st = *state_;
  if (!st.has_handles) throw std::invalid_argument("LocalGlobalArap::solve: call precompute and set_handles first");
  if (out == nullptr) throw std::invalid_argument("LocalGlobalArap::solve: out is null");
  detail::check_targets(st.handles, targets);
  if (initial.size() > 0) {
    ::qpreduce::check_size("LocalGlobalArap::solve: initial guess rows", st.n, initial.rows());
    ::qpreduce::check_finite("LocalGlobalArap::solve: initial guess", initial);
  }
  const Normalization& f = st.units;
  vertex_targets(st.given_targets, st.handles, targets, 1e-9 * f.scale);  // throws on conflicts, in the given units
  ReferenceSummary summary = detail::run_rounds(
      st, normalised(targets, f), out,
      initial.size() > 0 ? Vertices((initial.rowwise() - f.centre.transpose()) / f.scale) : Vertices(), cancel);
  detail::to_given_units(f, st.energy_unit, &summary, out);
  const bool accelerate = st.options.anderson_window > 0;
  summary.solver_report = fmt::format(
      "local-global ({}{}): {} rounds, energy {:.12g} -> {:.12g}, {}", to_string(st.options.energy),
      (accelerate ? fmt::format(", Anderson window {}, {} rejected", st.options.anderson_window, summary.rejected_steps)
                  : std::string()) +
          (summary.newton_steps > 0 ? fmt::format(", {} Newton steps ({} CG products, {} fell back)",
                                                  summary.newton_steps, summary.cg_iterations, summary.newton_fallbacks)
                                    : std::string()),
      summary.iterations, summary.initial_energy, summary.energy, summary.message);
  return summary;
}

void LocalGlobalArap::set_iteration_options(const ReferenceOptions& options) {
  State& st = *state_;
  if (st.n == 0) throw std::invalid_argument("LocalGlobalArap::set_iteration_options: call precompute first");
  std::string why;
  if (!options.is_valid(&why)) throw std::invalid_argument("ReferenceOptions: " + why);
  st.options.max_iterations = options.max_iterations;
  st.options.step_tolerance = options.step_tolerance;
  st.options.energy_tolerance = options.energy_tolerance;
  st.options.tolerance = options.tolerance;
  st.options.distance_tolerance = options.distance_tolerance;
  st.options.anderson_window = options.anderson_window;
  st.options.newton_after = options.newton_after;
  st.options.threads = options.threads;
}

const ReferenceOptions& LocalGlobalArap::options() const { return state_->options; }

ReferenceSummary solve_local_global(const DeformableMesh& model, const Handles& handles,
                                    const HandleTargets& targets, const ReferenceOptions& options,
                                    ReferenceSolution* out, const Vertices& initial) {
  if (out == nullptr) throw std::invalid_argument("reference: out is null");
  const Timer setup;
  LocalGlobalArap lg;  // in the units-free frame itself
  lg.precompute(model, options);
  const HandleSetSummary hs = lg.set_handles(handles);
  ReferenceSummary summary;
  if (!hs.ok()) {
    summary.status = hs.status;
    summary.message = hs.message;
    summary.setup_seconds = setup.seconds();
    return summary;
  }
  const double setup_seconds = setup.seconds();
  summary = lg.solve(targets, out, initial);
  summary.setup_seconds = setup_seconds;
  return summary;
}

}  // namespace qpreduce::deform
