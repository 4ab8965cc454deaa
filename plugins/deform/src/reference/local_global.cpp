// Local-global (Sorkine–Alexa) ARAP in full space, classic or modified
// energy, one cached factorization per handle set (reference.h).
#include "reference_internal.h"


#include <qpreduce/support.h>

#include <Eigen/Dense>
#include <Eigen/SparseCholesky>
#include <fmt/format.h>

#include <algorithm>
#include <cmath>

namespace qpreduce::deform {

namespace {

using Triplets = std::vector<Eigen::Triplet<double>>;
using detail_reference::PreparedModel;

}  // namespace

struct LocalGlobalArap::State {
  ReferenceOptions options;
  PreparedModel m;
  Index n = 0, nu = 0, s = 0;
  std::vector<Index> control_of_free;  // first control row of a free vertex, −1 in a patch
  SparseMatrix<double> P;              // 3n × n_u
  SparseMatrix<double> Hu;             // n_u × n_u
  // Classic: nothing more (the linear term is assembled per round).
  // Modified: q = D_s·S; Q = L_QQ⁻¹(D_Q S − L_QV V′); S-coefficient Dᵀ[V′; Q].
  SparseMatrix<double> Ds, D, DV, DQ, LQV;
  Eigen::SimplicialLLT<SparseMatrix<double>> LQQ;  // block diagonal, 4 × 4 blocks
  // Handle set.
  Handles handles;
  std::vector<Index> free_index;   // control row → index among free coordinates, −1 if pinned
  std::vector<Index> pinned_rows;  // control rows held by a constraint
  SparseMatrix<double> Hfp;        // free × pinned coupling
  SparseMatrix<double> Af, Ap;     // general rows (weighted handles): m_g × free, m_g × pinned
  std::vector<size_t> general_handles;  // point handle of each group of 3 general rows
  std::unique_ptr<SparseFactorization> factor;  // K + ρAfᵀAf
  Matrix<double> G;                             // (K + ρAfᵀAf)⁻¹Afᵀ
  Eigen::LDLT<Eigen::MatrixXd> schur;           // Af·G
  double rho = 0.0;
  bool has_handles = false;

  // Adds the control-layer entries of coordinate (v, a) scaled by `scale` to column `col`.
  void control_row(Index v, int a, double scale, Index col, Triplets* t) const {
    const int p = m.patch_of_vertex[v];
    if (p < 0) {
      t->emplace_back(control_of_free[v] + a, col, scale);
      return;
    }
    const Index base = nu - 12 * s + 12 * p;
    for (int c = 0; c < 3; ++c) t->emplace_back(base + 3 * a + c, col, scale * m.V(v, c));
    t->emplace_back(base + 9 + a, col, scale);
  }
};

LocalGlobalArap::LocalGlobalArap() : state_(std::make_unique<State>()) {}
LocalGlobalArap::~LocalGlobalArap() = default;
LocalGlobalArap::LocalGlobalArap(LocalGlobalArap&&) noexcept = default;
LocalGlobalArap& LocalGlobalArap::operator=(LocalGlobalArap&&) noexcept = default;

const RotationElements& LocalGlobalArap::elements() const { return state_->m.elements; }

void LocalGlobalArap::precompute(const DeformableMesh& model, const ReferenceOptions& options) {
  auto st = std::make_unique<State>();
  State& S = *st;
  S.options = options;
  S.m = detail_reference::prepare_model(model, options);
  S.n = S.m.V.rows();
  S.s = static_cast<Index>(S.m.patch_types.size());
  S.control_of_free.assign(static_cast<size_t>(S.n), -1);
  Index free_count = 0;
  for (Index v = 0; v < S.n; ++v)
    if (S.m.patch_of_vertex[v] < 0) S.control_of_free[v] = 3 * free_count++;
  S.nu = 3 * free_count + 12 * S.s;
  Triplets tp;
  for (Index v = 0; v < S.n; ++v)
    for (int a = 0; a < 3; ++a) S.control_row(v, a, 1.0, 3 * v + a, &tp);
  SparseMatrix<double> Pt(S.nu, 3 * S.n);  // control_row fills (control row, column) = Pᵀ
  Pt.setFromTriplets(tp.begin(), tp.end());
  S.P = Pt.transpose();

  SparseMatrix<double> H;
  if (options.energy == ReferenceEnergy::ClassicArap) {
    // H = Σ_k Σ_e c (ξ_i − ξ_j)(ξ_i − ξ_j)ᵀ ⊗ I₃.
    const RotationElements& el = S.m.elements;
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
    H.resize(3 * S.n, 3 * S.n);
    H.setFromTriplets(th.begin(), th.end());
  } else {
    const ModifiedArapSystem sys = assemble_modified_arap(S.m.V, S.m.elements, S.m.clusters, S.m.d, S.m.parameters);
    const EliminatedArapSystem elim = eliminate_rotation_corrections(sys);
    const Index nv = 3 * S.n, nq = 4 * sys.r;
    H = elim.H;
    S.Ds = elim.Ds;
    S.DV = elim.DV;
    S.D = sys.D;
    S.DQ = sys.D.bottomRows(nq);
    S.LQV = sys.L.block(nv, 0, nq, nv);
    S.LQQ.compute(SparseMatrix<double>(sys.L.bottomRightCorner(nq, nq)));
    if (S.LQQ.info() != Eigen::Success) {
      throw std::invalid_argument("LocalGlobalArap: the Q block of E' is not positive definite (alpha = 0?)");
    }
  }
  S.Hu = SparseMatrix<double>(Pt * H * S.P);
  state_ = std::move(st);
}

HandleSetSummary LocalGlobalArap::set_handles(const Handles& handles) {
  const Timer timer;
  State& S = *state_;
  HandleSetSummary summary;
  if (S.n == 0) throw std::invalid_argument("LocalGlobalArap::set_handles: call precompute first");
  detail_reference::check_handles(S.m, handles);
  detail_reference::check_anchored(S.m, handles);
  S.has_handles = false;
  S.handles = handles;
  // Pinned control rows: the 12 parameters of Fixed and prescribed patches,
  // and the coordinates of free vertices held by single-vertex handles.
  std::vector<char> pinned(static_cast<size_t>(S.nu), 0);
  for (Index p = 0; p < S.s; ++p) {
    const bool held = S.m.patch_types[p] == PatchType::Fixed ||
                      std::find(handles.patches.begin(), handles.patches.end(), p) != handles.patches.end();
    if (held)
      for (int c = 0; c < 12; ++c) pinned[S.nu - 12 * S.s + 12 * p + c] = 1;
  }
  S.general_handles.clear();
  Triplets tg;  // general rows over the whole control layer
  for (size_t h = 0; h < handles.points.size(); ++h) {
    const PointHandle& ph = handles.points[h];
    const bool single = ph.vertices.size() == 1 && (ph.weights.empty() || ph.weights[0] == 1.0);
    if (single) {
      const Index v = ph.vertices[0];
      const int p = S.m.patch_of_vertex[v];
      if (p < 0) {
        for (int a = 0; a < 3; ++a) pinned[S.control_of_free[v] + a] = 1;
        continue;
      }
      if (pinned[S.nu - 12 * S.s + 12 * p]) continue;  // held by its patch (targets compared in solve)
    }
    const Index row = 3 * static_cast<Index>(S.general_handles.size());
    for (size_t i = 0; i < ph.vertices.size(); ++i)
      for (int a = 0; a < 3; ++a) S.control_row(ph.vertices[i], a, ph.weights.empty() ? 1.0 : ph.weights[i], row + a, &tg);
    S.general_handles.push_back(h);
  }
  S.free_index.assign(static_cast<size_t>(S.nu), -1);
  std::vector<Index> pinned_index(static_cast<size_t>(S.nu), -1);
  S.pinned_rows.clear();
  Index nf = 0;
  for (Index r = 0; r < S.nu; ++r) {
    if (pinned[r]) {
      pinned_index[r] = static_cast<Index>(S.pinned_rows.size());
      S.pinned_rows.push_back(r);
    } else {
      S.free_index[r] = nf++;
    }
  }
  const Index np = static_cast<Index>(S.pinned_rows.size());
  const Index mg = 3 * static_cast<Index>(S.general_handles.size());
  // Split Hu and the general rows into free and pinned columns.
  Triplets tff, tfp, taf, tap;
  for (Index c = 0; c < S.nu; ++c)
    for (SparseMatrix<double>::InnerIterator it(S.Hu, c); it; ++it) {
      const Index r = it.row();
      if (S.free_index[r] < 0) continue;
      if (S.free_index[c] >= 0) tff.emplace_back(S.free_index[r], S.free_index[c], it.value());
      else tfp.emplace_back(S.free_index[r], pinned_index[c], it.value());
    }
  for (const auto& t : tg) {
    if (S.free_index[t.row()] >= 0) taf.emplace_back(t.col(), S.free_index[t.row()], t.value());
    else tap.emplace_back(t.col(), pinned_index[t.row()], t.value());
  }
  SparseMatrix<double> K(nf, nf);
  K.setFromTriplets(tff.begin(), tff.end());
  S.Hfp.resize(nf, np);
  S.Hfp.setFromTriplets(tfp.begin(), tfp.end());
  S.Af.resize(mg, nf);
  S.Af.setFromTriplets(taf.begin(), taf.end());
  S.Ap.resize(mg, np);
  S.Ap.setFromTriplets(tap.begin(), tap.end());
  if (mg > 0) {
    // ρ: the scale of K's diagonal over that of AfᵀAf, so the augmentation
    // neither dominates nor vanishes in rounding (the KKT answer does not
    // depend on ρ).
    const SparseMatrix<double> AtA = SparseMatrix<double>(S.Af.transpose() * S.Af);
    const double kd = K.diagonal().cwiseAbs().mean(), ad = AtA.diagonal().cwiseAbs().maxCoeff();
    if (!(ad > 0)) throw std::invalid_argument("LocalGlobalArap: a weighted point handle has only zero weights");
    S.rho = kd / ad;
    K += S.rho * AtA;
  }
  S.factor = make_factorization(S.options.backend);
  S.factor->compute(K);
  summary.free_coordinates = nf;
  summary.pinned_coordinates = np;
  summary.point_rows = mg;
  if (S.factor->info() != Eigen::Success) {
    summary.status = Status::NumericalFailure;
    summary.message = "global step matrix: " + S.factor->message();
    summary.seconds = timer.seconds();
    return summary;
  }
  if (mg > 0) {
    S.G = Matrix<double>(S.Af.transpose());
    S.factor->solveInPlace(S.G, 64);
    const Eigen::MatrixXd schur = S.Af * S.G;
    S.schur.compute(schur);
    const double dmax = S.schur.vectorD().cwiseAbs().maxCoeff();
    if (S.schur.info() != Eigen::Success || !(S.schur.vectorD().minCoeff() > 1e-12 * dmax)) {
      throw std::invalid_argument(
          "LocalGlobalArap: the weighted point handles are linearly dependent (two handles constrain the same "
          "combination of vertices)");
    }
  }
  S.has_handles = true;
  summary.status = Status::Success;
  summary.message = fmt::format("{} free coordinates, {} pinned, {} weighted-point rows", nf, np, mg);
  summary.seconds = timer.seconds();
  return summary;
}

ReferenceSummary LocalGlobalArap::solve(const HandleTargets& targets, ReferenceSolution* out, const Vertices& initial) {
  State& S = *state_;
  if (!S.has_handles) throw std::invalid_argument("LocalGlobalArap::solve: call precompute and set_handles first");
  detail_reference::check_targets(S.handles, targets);
  const PreparedModel& m = S.m;
  const Index n = S.n;
  if (initial.size() > 0) {
    ::qpreduce::check_size("LocalGlobalArap::solve: initial guess rows", n, initial.rows());
    ::qpreduce::check_finite("LocalGlobalArap::solve: initial guess", initial);
  }
  const bool classic = S.options.energy == ReferenceEnergy::ClassicArap;
  const Eigen::Matrix3d frame = classic ? Eigen::Matrix3d::Identity() : S.options.frame;
  const Eigen::Matrix3d Ft = frame.transpose();
  DeformableMesh targets_model;  // vertex_targets only reads V and the patches
  targets_model.V = m.V;
  targets_model.patch_of_vertex = m.patch_of_vertex;
  targets_model.patch_types = m.patch_types;
  vertex_targets(targets_model, S.handles, targets, 1e-9 * m.diagonal);  // throws on conflicts

  const Timer timer;
  ReferenceSummary summary;
  summary.energy_kind = S.options.energy;
  // Pinned values u_p and general right-hand sides b_g, in the solve frame.
  Eigen::VectorXd up(static_cast<Index>(S.pinned_rows.size()));
  {
    Eigen::VectorXd u = Eigen::VectorXd::Zero(S.nu);
    for (const auto& pt : detail_reference::patch_targets(m, S.handles, targets, frame)) {
      const Index base = S.nu - 12 * S.s + 12 * pt.patch;
      for (int a = 0; a < 3; ++a)
        for (int c = 0; c < 3; ++c) u(base + 3 * a + c) = pt.transform(a, c);
      u.segment<3>(base + 9) = pt.transform.col(3);
    }
    for (size_t h = 0; h < S.handles.points.size(); ++h) {
      const PointHandle& ph = S.handles.points[h];
      if (ph.vertices.size() != 1 || m.patch_of_vertex[ph.vertices[0]] >= 0) continue;
      if (!(ph.weights.empty() || ph.weights[0] == 1.0)) continue;
      u.segment<3>(S.control_of_free[ph.vertices[0]]) = Ft * targets.points.row(static_cast<Index>(h)).transpose();
    }
    for (size_t k = 0; k < S.pinned_rows.size(); ++k) up(static_cast<Index>(k)) = u(S.pinned_rows[k]);
  }
  Eigen::VectorXd bg(3 * static_cast<Index>(S.general_handles.size()));
  for (size_t g = 0; g < S.general_handles.size(); ++g)
    bg.segment<3>(3 * static_cast<Index>(g)) = Ft * targets.points.row(static_cast<Index>(S.general_handles[g])).transpose();
  bg -= S.Ap * up;
  const Eigen::VectorXd rhs_pinned = S.Hfp * up;

  // Pose and rotations in the solve frame.
  Vertices X = initial.size() > 0 ? Vertices(initial * frame) : m.V;  // rows: (Fᵀ v)ᵀ = vᵀF
  const RotationElements& el = m.elements;
  const Index r = el.size();
  Eigen::VectorXd R(classic ? 9 * r : 9 * m.d), Q = Eigen::VectorXd::Zero(classic ? 0 : 4 * r);
  Eigen::VectorXd qV(3 * n), qu(S.nu), u(S.nu);
  Matrix<double> rhs(S.nu - up.size(), 1);

  auto edge = [&](const Vertices& Y, Index e) -> Eigen::Vector3d {
    return (Y.row(el.edge_i[e]) - Y.row(el.edge_j[e])).transpose();
  };
  // Local step: rotations from the pose X (and Q for E′); returns the energy.
  auto local_step = [&]() -> double {
    if (classic) {
      double energy = 0.0;
      for (Index k = 0; k < r; ++k) {
        Eigen::Matrix3d Gk = Eigen::Matrix3d::Zero();
        for (Index e = el.offsets[k]; e < el.offsets[k + 1]; ++e)
          Gk.noalias() += el.weight[e] * edge(X, e) * edge(m.V, e).transpose();
        const Eigen::Matrix3d Rk = fit_rotation(Gk);
        Eigen::Map<Eigen::Matrix3d>(R.data() + 9 * k) = Rk;
        for (Index e = el.offsets[k]; e < el.offsets[k + 1]; ++e)
          energy += 0.5 * el.weight[e] * (edge(X, e) - Rk * edge(m.V, e)).squaredNorm();
      }
      return energy;
    }
    const Eigen::Map<const Eigen::VectorXd> xv(X.data(), 3 * n);
    Eigen::VectorXd coeff;
    if (S.options.cluster_fit == ClusterRotationFit::Exact) {
      Eigen::VectorXd uq(3 * n + 4 * r);
      uq << xv, Q;
      coeff = S.D.transpose() * uq;
    } else {
      coeff = S.DV.transpose() * xv;
    }
    for (Index i = 0; i < m.d; ++i)
      Eigen::Map<Eigen::Matrix3d>(R.data() + 9 * i) = fit_rotation(Eigen::Map<const Eigen::Matrix3d>(coeff.data() + 9 * i));
    return modified_arap_energy(m.V, el, m.clusters, m.parameters, X, Q, R);
  };
  auto linear_term = [&]() {
    if (!classic) {
      qV = S.Ds * R;
      return;
    }
    qV.setZero();
    for (Index k = 0; k < r; ++k) {
      const Eigen::Map<const Eigen::Matrix3d> Rk(R.data() + 9 * k);
      for (Index e = el.offsets[k]; e < el.offsets[k + 1]; ++e) {
        const Eigen::Vector3d t = el.weight[e] * (Rk * edge(m.V, e));
        qV.segment<3>(3 * el.edge_i[e]) += t;
        qV.segment<3>(3 * el.edge_j[e]) -= t;
      }
    }
  };

  // Rotations of the initial pose (the identities at rest).
  if (classic || initial.size() > 0) {
    summary.initial_energy = local_step();
  } else {
    for (Index i = 0; i < m.d; ++i) Eigen::Map<Eigen::Matrix3d>(R.data() + 9 * i).setIdentity();
    summary.initial_energy = modified_arap_energy(m.V, el, m.clusters, m.parameters, X, Q, R);
  }
  double energy = summary.initial_energy;
  summary.status = Status::Success;
  int it = 0;
  for (; it < S.options.max_iterations; ++it) {
    // Global step: K u_f + Af ᵀλ = q_f − Hfp u_p, Af u_f = b_g (augmented, see set_handles).
    linear_term();
    qu = S.P.transpose() * qV;
    for (Index row = 0; row < S.nu; ++row)
      if (S.free_index[row] >= 0) rhs(S.free_index[row], 0) = qu(row);
    rhs.col(0) -= rhs_pinned;
    if (bg.size() > 0) rhs.col(0) += S.rho * (S.Af.transpose() * bg);
    S.factor->solveInPlace(rhs, 1);
    if (bg.size() > 0) {
      const Eigen::VectorXd mu = S.schur.solve(S.Af * rhs.col(0) - bg);
      rhs.col(0) -= S.G * mu;
    }
    for (Index row = 0; row < S.nu; ++row)
      u(row) = S.free_index[row] >= 0 ? rhs(S.free_index[row], 0) : 0.0;
    for (size_t k = 0; k < S.pinned_rows.size(); ++k) u(S.pinned_rows[k]) = up(static_cast<Index>(k));
    const Eigen::VectorXd xv = S.P * u;
    const Eigen::Map<const Vertices> Xnew(xv.data(), n, 3);
    summary.last_step = (Xnew - X).rowwise().norm().maxCoeff();
    X = Xnew;
    if (!classic) Q = S.LQQ.solve(S.DQ * R - S.LQV * xv);
    if (!X.allFinite()) {
      summary.status = Status::NumericalFailure;
      summary.message = fmt::format("non-finite positions in round {}", it + 1);
      break;
    }
    const double next = local_step();
    const double drop = std::abs(energy - next) / std::max(std::abs(next), 1e-300);
    energy = next;
    if (summary.last_step <= S.options.step_tolerance * m.diagonal && drop <= S.options.energy_tolerance) {
      summary.converged = true;
      ++it;
      break;
    }
  }
  summary.iterations = it;
  summary.solve_seconds = timer.seconds();
  // Back to the world frame.
  out->V = X * Ft;  // rows: (F x)ᵀ = xᵀFᵀ
  out->Q = Q;
  out->rotations = R;
  if (!classic)
    for (Index i = 0; i < m.d; ++i) {
      Eigen::Map<Eigen::Matrix3d> Si(out->rotations.data() + 9 * i);
      Si = frame * Si;
    }
  summary.energy = energy;  // of the returned (V′, R) or (V′, Q, S)
  summary.handle_residual = handle_residual(targets_model, S.handles, targets, out->V);
  if (summary.status == Status::Success && !summary.converged) {
    summary.message = fmt::format("iteration limit ({}) reached; last step {:.3e} of the bounding-box diagonal",
                                  S.options.max_iterations, summary.last_step / m.diagonal);
  } else if (summary.status == Status::Success) {
    summary.message = fmt::format("converged in {} rounds", it);
  }
  summary.solver_report = fmt::format("local-global ({}): {} rounds, energy {:.12g} -> {:.12g}, {}",
                                      to_string(S.options.energy), it, summary.initial_energy, summary.energy,
                                      summary.message);
  return summary;
}

ReferenceSummary solve_local_global(const DeformableMesh& model, const Handles& handles,
                                    const HandleTargets& targets, const ReferenceOptions& options,
                                    ReferenceSolution* out, const Vertices& initial) {
  const Timer setup;
  LocalGlobalArap lg;
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
