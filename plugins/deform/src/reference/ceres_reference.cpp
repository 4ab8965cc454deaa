// Ceres Solver full-space minimiser of the classic ARAP energy or of E′
// (reference.h): rotations as unit quaternions on ceres::QuaternionManifold,
// constrained vertices as constant parameter blocks, automatic derivatives.
#include "reference_internal.h"

#include <qpreduce/checks.h>
#include <qpreduce/util/timer.h>

#ifdef QPREDUCE_NO_CERES

#include <stdexcept>

namespace qpreduce::deform {

bool has_ceres_reference() { return false; }

ReferenceSummary solve_ceres_reference(const DeformableMesh&, const Handles&, const HandleTargets&,
                                       const ReferenceOptions&, ReferenceSolution*, const Vertices&) {
  throw std::runtime_error(
      "solve_ceres_reference: qpreduce was built without Ceres (QPREDUCE_NO_CERES); "
      "install Ceres 2.1 and reconfigure, or use LocalGlobalArap");
}

}  // namespace qpreduce::deform

#else

#include <ceres/ceres.h>
#include <ceres/rotation.h>
#include <Eigen/Dense>
#include <Eigen/Geometry>
#include <fmt/format.h>

#include <algorithm>
#include <array>

namespace qpreduce::deform {

namespace {

using detail::PreparedModel;

// One residual block: the corners of one triangle (tet) of an element, and
// B (corners − 1 rows) with BᵀB = Σ_e c_e (ξ_i − ξ_j)(ξ_i − ξ_j)ᵀ over the
// element's edges in that triangle (tet).
template <int K>
struct Stencil {
  std::array<Index, K> corner;
  Eigen::Matrix<double, K - 1, K> B;
};

template <int K>
Stencil<K> make_stencil(const RotationElements& el, Index first_edge) {
  constexpr int edges = K == 3 ? 3 : 6;
  Stencil<K> st;
  int used = 0;
  for (int e = 0; e < edges; ++e)
    for (Index v : {static_cast<Index>(el.edge_i[first_edge + e]), static_cast<Index>(el.edge_j[first_edge + e])})
      if (std::find(st.corner.begin(), st.corner.begin() + used, v) == st.corner.begin() + used) st.corner[used++] = v;
  Eigen::Matrix<double, K, K> L = Eigen::Matrix<double, K, K>::Zero();
  for (int e = 0; e < edges; ++e) {
    const auto at = [&](Index v) { return std::find(st.corner.begin(), st.corner.end(), v) - st.corner.begin(); };
    const auto a = at(el.edge_i[first_edge + e]), b = at(el.edge_j[first_edge + e]);
    const double c = el.weight[first_edge + e];
    L(a, a) += c;
    L(b, b) += c;
    L(a, b) -= c;
    L(b, a) -= c;
  }
  // L is PSD with the constants as null vector: drop the smallest eigenpair.
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, K, K>> es(L);
  for (int j = 0; j < K - 1; ++j)
    st.B.row(j) = std::sqrt(std::max(0.0, es.eigenvalues()(j + 1))) * es.eigenvectors().col(j + 1).transpose();
  return st;
}

// Residual (B ⊗ I₃)·δ over the K corners of a stencil, with
//   classic: δ_c = v′_c − r·v_c,                      parameters (r, v′_1..K);
//   E′:      δ_c = v′_c − s·v_c − (q0·v_c + ω × v_c),  parameters (s, Q, v′_1..K);
// r and s unit quaternions.
template <int K, bool Modified>
struct StencilResidual {
  Stencil<K> st;
  Eigen::Matrix<double, K, 3> rest;
  template <typename T>
  bool operator()(T const* const* p, T* res) const {
    constexpr int first_corner = Modified ? 2 : 1;
    T delta[K][3];
    for (int c = 0; c < K; ++c) {
      const T x[3] = {T(rest(c, 0)), T(rest(c, 1)), T(rest(c, 2))};
      T rx[3];
      ceres::UnitQuaternionRotatePoint(p[0], x, rx);
      for (int a = 0; a < 3; ++a) delta[c][a] = p[first_corner + c][a] - rx[a];
      if (Modified) {
        const T* q = p[1];
        const T wx[3] = {q[2] * x[2] - q[3] * x[1], q[3] * x[0] - q[1] * x[2], q[1] * x[1] - q[2] * x[0]};
        for (int a = 0; a < 3; ++a) delta[c][a] -= q[0] * x[a] + wx[a];
      }
    }
    for (int j = 0; j < K - 1; ++j)
      for (int a = 0; a < 3; ++a) {
        T sum(0.0);
        for (int c = 0; c < K; ++c) sum += st.B(j, c) * delta[c][a];
        res[3 * j + a] = sum;
      }
    return true;
  }
};

// The Eq. 10 penalty ½QᵀMQ as ½‖U·Q‖², UᵀU = M (4 × 4 SPD).
struct PenaltyResidual {
  Eigen::Matrix4d U;
  template <typename T>
  bool operator()(const T* q, T* res) const {
    for (int i = 0; i < 4; ++i) {
      res[i] = T(0.0);
      for (int j = 0; j < 4; ++j) res[i] += U(i, j) * q[j];
    }
    return true;
  }
};

Eigen::Vector4d to_quaternion(const Eigen::Matrix3d& R) {
  const Eigen::Quaterniond q(R);
  return {q.w(), q.x(), q.y(), q.z()};
}

Eigen::Matrix3d to_rotation(const double* q) {
  return Eigen::Quaterniond(q[0], q[1], q[2], q[3]).normalized().toRotationMatrix();
}

template <int K>
void add_element_residuals(ceres::Problem* problem, const PreparedModel& m, bool classic, Index k, double* rotation,
                           double* Qk, Vertices* X) {
  const RotationElements& el = m.elements;
  constexpr int edges = K == 3 ? 3 : 6;
  for (Index e = el.offsets[k]; e < el.offsets[k + 1]; e += edges) {
    const Stencil<K> st = make_stencil<K>(el, e);
    Eigen::Matrix<double, K, 3> rest;
    std::vector<double*> blocks{rotation};
    if (!classic) blocks.push_back(Qk);
    for (int c = 0; c < K; ++c) {
      rest.row(c) = m.V.row(st.corner[c]);
      blocks.push_back(X->data() + 3 * st.corner[c]);
    }
    ceres::DynamicCostFunction* cost = nullptr;
    if (classic) {
      cost = new ceres::DynamicAutoDiffCostFunction<StencilResidual<K, false>, 16>(
          new StencilResidual<K, false>{st, rest});
      cost->AddParameterBlock(4);
    } else {
      cost = new ceres::DynamicAutoDiffCostFunction<StencilResidual<K, true>, 16>(
          new StencilResidual<K, true>{st, rest});
      cost->AddParameterBlock(4);
      cost->AddParameterBlock(4);
    }
    for (int c = 0; c < K; ++c) cost->AddParameterBlock(3);
    cost->SetNumResiduals(3 * (K - 1));
    problem->AddResidualBlock(cost, nullptr, blocks);
  }
}

// The Ceres reference supports single-vertex handles and Fixed or prescribed
// patches only; throws std::invalid_argument otherwise.
void check_supported(const PreparedModel& m, const Handles& handles) {
  for (size_t h = 0; h < handles.points.size(); ++h) {
    const PointHandle& ph = handles.points[h];
    if (ph.vertices.size() != 1 || !(ph.weights.empty() || ph.weights[0] == 1.0)) {
      throw std::invalid_argument(fmt::format(
          "solve_ceres_reference: point handle {} is a weighted group; only single-vertex handles are supported "
          "(use the local-global reference)",
          h));
    }
  }
  for (Index v = 0; v < m.V.rows(); ++v) {
    const int p = m.patch_of_vertex[v];
    if (p >= 0 && m.patch_types[p] != PatchType::Fixed &&
        std::find(handles.patches.begin(), handles.patches.end(), p) == handles.patches.end()) {
      throw std::invalid_argument(fmt::format(
          "solve_ceres_reference: patch {} is neither Fixed nor prescribed (a free affine patch); not supported "
          "(use the local-global reference)",
          p));
    }
  }
}

// Start rotations (4 × nrot quaternions): fitted to the start pose X (solve
// frame) when there is an initial guess, else the identities (at rest).
Eigen::VectorXd start_rotations(const PreparedModel& m, bool classic, Index nrot, const Vertices& X, bool fitted) {
  const RotationElements& el = m.elements;
  Eigen::VectorXd quats(4 * nrot);
  std::vector<Eigen::Matrix3d> G(static_cast<size_t>(nrot), Eigen::Matrix3d::Zero());
  for (Index k = 0; k < el.size(); ++k)
    for (Index e = el.offsets[k]; e < el.offsets[k + 1]; ++e) {
      const Eigen::Vector3d ev = (m.V.row(el.edge_i[e]) - m.V.row(el.edge_j[e])).transpose();
      const Eigen::Vector3d ep = (X.row(el.edge_i[e]) - X.row(el.edge_j[e])).transpose();
      G[static_cast<size_t>(classic ? k : m.clusters[k])] += el.weight[e] * ep * ev.transpose();
    }
  for (Index i = 0; i < nrot; ++i)
    quats.segment<4>(4 * i) = fitted ? to_quaternion(fit_rotation(G[static_cast<size_t>(i)])) : Eigen::Vector4d(1, 0, 0, 0);
  return quats;
}

// E′'s penalty on Q_k: the Cholesky factor of the Hessian of
// α·a(3q0² + 2‖ω‖²) + β·a(q0² + ‖ω‖² − (ω·n)²) (Eq. 10), as a residual block.
void add_penalty(ceres::Problem* problem, const PreparedModel& m, Index k, double* qk) {
  const RotationElements& el = m.elements;
  const double a = el.measure(k), beta = el.is_surface ? m.parameters.beta : 0.0;
  Eigen::Matrix4d M = Eigen::Matrix4d::Zero();
  M(0, 0) = 2.0 * a * (3.0 * m.parameters.alpha + beta);
  M.bottomRightCorner<3, 3>() = 2.0 * a * (2.0 * m.parameters.alpha + beta) * Eigen::Matrix3d::Identity();
  if (beta > 0.0) {
    const Eigen::Vector3d nk = el.normal.row(k).transpose();
    M.bottomRightCorner<3, 3>() -= 2.0 * a * beta * nk * nk.transpose();
  }
  const Eigen::LLT<Eigen::Matrix4d> llt(M);
  if (llt.info() != Eigen::Success) {
    throw std::invalid_argument(fmt::format("solve_ceres_reference: the Eq. 10 penalty of element {} is not "
                                            "positive definite (zero measure?)",
                                            k));
  }
  problem->AddResidualBlock(
      new ceres::AutoDiffCostFunction<PenaltyResidual, 4, 4>(new PenaltyResidual{llt.matrixU()}), nullptr, qk);
}

// The Ceres solver options of `options`; throws std::invalid_argument when
// Ceres refuses them.
ceres::Solver::Options solver_options(const ReferenceOptions& options) {
  ceres::Solver::Options so;
  so.minimizer_type = ceres::TRUST_REGION;
  so.trust_region_strategy_type = ceres::LEVENBERG_MARQUARDT;
  so.linear_solver_type = ceres::SPARSE_NORMAL_CHOLESKY;
  so.max_num_iterations = options.max_iterations;
  so.function_tolerance = options.function_tolerance;
  so.gradient_tolerance = options.gradient_tolerance;
  so.parameter_tolerance = options.parameter_tolerance;
  so.num_threads = options.threads;
  so.logging_type = ceres::SILENT;
  std::string why;
  if (!so.IsValid(&why)) throw std::invalid_argument("solve_ceres_reference: Ceres options: " + why);
  return so;
}

// Status, message and counts of a Ceres run.
void read_ceres_summary(const ceres::Solver::Summary& cs, bool finite, ReferenceSummary* summary) {
  summary->solver_report = cs.FullReport();
  summary->iterations = static_cast<int>(cs.iterations.size()) - 1;
  summary->initial_energy = cs.initial_cost;
  summary->converged = cs.termination_type == ceres::CONVERGENCE;
  if (cs.termination_type == ceres::FAILURE || cs.termination_type == ceres::USER_FAILURE || !finite) {
    summary->status = Status::NumericalFailure;
    summary->message = "Ceres: " + cs.message;
  } else {
    summary->status = Status::Success;
    summary->message = fmt::format("Ceres {}: {}", ceres::TerminationTypeToString(cs.termination_type), cs.message);
  }
}

// The solve in the frame solve_ceres_reference gives it.
ReferenceSummary solve_ceres_in_frame(const DeformableMesh& model, const Handles& handles, const HandleTargets& targets,
                                      const ReferenceOptions& options, ReferenceSolution* out,
                                      const Vertices& initial) {
  const Timer setup;
  const PreparedModel m = detail::prepare_model(model, options);
  detail::check_handles(m, handles);
  detail::check_anchored(m, handles);
  check_supported(m, handles);
  const Index n = m.V.rows();
  if (initial.size() > 0) {
    ::qpreduce::check_size("solve_ceres_reference: initial guess rows", n, initial.rows());
    ::qpreduce::check_finite("solve_ceres_reference: initial guess", initial);
  }
  const DeformableMesh targets_model = detail::targets_model(m);
  const VertexTargets pinned = vertex_targets(targets_model, handles, targets, 1e-9 * m.diagonal);

  const bool classic = options.energy == ReferenceEnergy::ClassicArap;
  const Eigen::Matrix3d frame = classic ? Eigen::Matrix3d::Identity() : options.frame;
  const RotationElements& el = m.elements;
  const Index r = el.size();
  // Unknowns in the solve frame (rows (Fᵀx)ᵀ = xᵀF).
  Vertices X = initial.size() > 0 ? Vertices(initial * frame) : m.V;
  for (Index v = 0; v < n; ++v)
    if (pinned.pinned[v]) X.row(v) = pinned.position.row(v) * frame;
  const Index nrot = classic ? r : m.d;
  Eigen::VectorXd quats = start_rotations(m, classic, nrot, X, initial.size() > 0);
  Eigen::VectorXd Q = Eigen::VectorXd::Zero(classic ? 0 : 4 * r);
  ceres::Problem::Options popts;
  popts.manifold_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  ceres::Problem problem(popts);
  ceres::QuaternionManifold quaternion_manifold;
  for (Index k = 0; k < r; ++k) {
    if (el.offsets[k] == el.offsets[k + 1]) continue;
    double* rot = quats.data() + 4 * (classic ? k : m.clusters[k]);
    double* qk = classic ? nullptr : Q.data() + 4 * k;
    if (m.tet) add_element_residuals<4>(&problem, m, classic, k, rot, qk, &X);
    else add_element_residuals<3>(&problem, m, classic, k, rot, qk, &X);
    if (!classic) add_penalty(&problem, m, k, qk);
  }
  for (Index i = 0; i < nrot; ++i)
    if (problem.HasParameterBlock(quats.data() + 4 * i)) problem.SetManifold(quats.data() + 4 * i, &quaternion_manifold);
  for (Index v = 0; v < n; ++v)
    if (pinned.pinned[v] && problem.HasParameterBlock(X.data() + 3 * v)) problem.SetParameterBlockConstant(X.data() + 3 * v);

  const ceres::Solver::Options so = solver_options(options);
  ReferenceSummary summary;
  summary.energy_kind = options.energy;
  summary.setup_seconds = setup.seconds();
  const Timer timer;
  ceres::Solver::Summary cs;
  ceres::Solve(so, &problem, &cs);
  summary.solve_seconds = timer.seconds();
  read_ceres_summary(cs, X.allFinite(), &summary);
  Eigen::VectorXd R(9 * nrot);
  for (Index i = 0; i < nrot; ++i) Eigen::Map<Eigen::Matrix3d>(R.data() + 9 * i) = to_rotation(quats.data() + 4 * i);
  summary.energy = detail::energy_of(m, options.energy, X, Q, R);
  out->V = X * frame.transpose();
  out->Q = Q;
  out->rotations = R;
  if (!classic) detail::rotations_to_world(frame, &out->rotations);
  summary.handle_residual = handle_residual(targets_model, handles, targets, out->V);
  return summary;
}

}  // namespace

bool has_ceres_reference() { return true; }

ReferenceSummary solve_ceres_reference(const DeformableMesh& model, const Handles& handles,
                                       const HandleTargets& targets, const ReferenceOptions& options,
                                       ReferenceSolution* out, const Vertices& initial) {
  // In the units-free frame (reference_internal.h): Ceres' gradient
  // tolerance, for one, is absolute.
  return detail::solve_in_frame(model, targets, initial, out,
                                          [&](const DeformableMesh& local_model, const HandleTargets& local_targets,
                                              const Vertices& local_initial, ReferenceSolution* local_out) {
                                            return solve_ceres_in_frame(local_model, handles, local_targets, options,
                                                                        local_out, local_initial);
                                          });
}

}  // namespace qpreduce::deform

#endif  // QPREDUCE_NO_CERES
