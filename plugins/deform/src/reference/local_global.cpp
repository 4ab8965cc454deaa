// Local-global (Sorkine–Alexa) ARAP in full space, classic or modified
// energy, one cached factorization per handle set (reference.h).
#include "reference_internal.h"
#include "deformer/control_layer.h"

#include <qpreduce/anderson.h>
#include <qpreduce/support.h>

#include <Eigen/Dense>
#include <Eigen/SparseCholesky>
#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <utility>

namespace qpreduce::deform {

namespace detail_reference {

using Triplets = std::vector<Eigen::Triplet<double>>;

// The state of a LocalGlobalArap: the global-step operators (precompute) and
// one handle set's split and factorization (set_handles).
struct LocalGlobalState {
  ReferenceOptions options;
  // m is the given model in the units-free frame (handles.h); everything
  // below computes there, solve maps targets in and results out.
  Normalization units;
  double energy_unit = 1.0;         // an energy of the frame times this is in the given units
  RotationElements given_elements;  // m.elements in the given units (elements())
  PreparedModel m;
  // The rest pose and patches that the handle residual (frame_targets) and
  // the conflict test of solve's targets (given_targets, the given units)
  // read, built once here rather than per solve.
  DeformableMesh frame_targets, given_targets;
  Index n = 0, nu = 0, s = 0;
  std::vector<Index> control_of_free;  // first control row of a free vertex, −1 in a patch
  SparseMatrix<double> P;              // 3n × n_u
  SparseMatrix<double> Hu;             // n_u × n_u
  // Classic: the rest edges e (3 × E, the elements' edges in order); the
  // edges at each vertex (CSR over n + 1 offsets; e + 1 where the vertex is
  // edge_i, −(e + 1) where it is edge_j); and per element the unit normal n
  // when all its rest edges lie in n⊥ (fit_rotation_planar), else zero.
  Eigen::Matrix<double, 3, Eigen::Dynamic> rest_edge;
  std::vector<Index> incident_offsets;
  std::vector<Index> incident_edges;
  Eigen::Matrix<double, 3, Eigen::Dynamic> plane_normal;
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
    detail_deformer::add_control_row(m.patch_of_vertex, m.V, control_of_free, nu - 12 * s, v, a, scale, col, t);
  }
};

}  // namespace detail_reference

struct LocalGlobalArap::State : detail_reference::LocalGlobalState {};

namespace {

using detail_reference::LocalGlobalState;
using detail_reference::PreparedModel;
using detail_reference::Triplets;

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

// ---- solve

// The constraint values in the solve frame: u_p (pinned rows), and the
// general rows' right-hand side b_g − A_p·u_p; with Hfp·u_p.
struct ConstrainedValues {
  Eigen::VectorXd up, bg, rhs_pinned;
};

ConstrainedValues constrained_values(const LocalGlobalState& st, const HandleTargets& targets,
                                     const Eigen::Matrix3d& frame) {
  const PreparedModel& m = st.m;
  const Eigen::Matrix3d Ft = frame.transpose();
  ConstrainedValues cv;
  cv.up.resize(static_cast<Index>(st.pinned_rows.size()));
  {
    Eigen::VectorXd u = Eigen::VectorXd::Zero(st.nu);
    for (const auto& pt : detail_reference::patch_targets(m, st.handles, targets, frame)) {
      const Index base = st.nu - 12 * st.s + 12 * pt.patch;
      for (int a = 0; a < 3; ++a)
        for (int c = 0; c < 3; ++c) u(base + 3 * a + c) = pt.transform(a, c);
      u.segment<3>(base + 9) = pt.transform.col(3);
    }
    for (size_t h = 0; h < st.handles.points.size(); ++h) {
      const PointHandle& ph = st.handles.points[h];
      if (ph.vertices.size() != 1 || m.patch_of_vertex[ph.vertices[0]] >= 0) continue;
      if (!(ph.weights.empty() || ph.weights[0] == 1.0)) continue;
      u.segment<3>(st.control_of_free[ph.vertices[0]]) = Ft * targets.points.row(static_cast<Index>(h)).transpose();
    }
    for (size_t k = 0; k < st.pinned_rows.size(); ++k) cv.up(static_cast<Index>(k)) = u(st.pinned_rows[k]);
  }
  cv.bg.resize(3 * static_cast<Index>(st.general_handles.size()));
  for (size_t g = 0; g < st.general_handles.size(); ++g)
    cv.bg.segment<3>(3 * static_cast<Index>(g)) =
        Ft * targets.points.row(static_cast<Index>(st.general_handles[g])).transpose();
  cv.bg -= st.Ap * cv.up;
  cv.rhs_pinned = st.Hfp * cv.up;
  return cv;
}

// The pose and rotations of one solve, in the solve frame, with the local
// and global steps of the alternation.
class Rounds {
 public:
  Rounds(const LocalGlobalState& st, bool classic, Vertices X0)
      : st_(st), m_(st.m), el_(st.m.elements), classic_(classic), n_(st.n), r_(st.m.elements.size()),
        threads_(st.options.threads),
        X(std::move(X0)), R(classic ? 9 * r_ : 9 * st.m.d), Q(Eigen::VectorXd::Zero(classic ? 0 : 4 * r_)),
        qV_(3 * n_), qu_(st.nu), u_(st.nu), rhs_(st.nu - static_cast<Index>(st.pinned_rows.size()), 1) {
    if (classic_) {
      XT_.resize(3, n_);
      t_.resize(3, st.rest_edge.cols());
      element_energy_.resize(r_);
    }
  }

  // Rotations from the pose X (and Q for E′); returns the energy.
  double local_step() {
    if (classic_) {
      // Per element k: G_k = Σ c e′eᵀ, R_k = argmax tr(RᵀG_k), its energy
      // ½Σ c‖e′ − R_k e‖², and t_e = c·R_k·e for the global step's linear
      // term. Elements in parallel; the energies are summed in element order
      // afterwards, so the result does not depend on the thread count.
      XT_ = X.transpose();
#pragma omp parallel for schedule(static) num_threads(threads_) if (threads_ > 1 && r_ >= 2048)
      for (Index k = 0; k < r_; ++k) {
        Eigen::Matrix3d Gk = Eigen::Matrix3d::Zero();
        for (Index e = el_.offsets[k]; e < el_.offsets[k + 1]; ++e)
          Gk.noalias() += (el_.weight[e] * (XT_.col(el_.edge_i[e]) - XT_.col(el_.edge_j[e]))) *
                          st_.rest_edge.col(e).transpose();
        const Eigen::Vector3d normal = st_.plane_normal.col(k);
        const Eigen::Matrix3d Rk = normal.squaredNorm() > 0.0 ? fit_rotation_planar(Gk, normal) : fit_rotation(Gk);
        Eigen::Map<Eigen::Matrix3d>(R.data() + 9 * k) = Rk;
        if (keep_curvature_) Eigen::Map<Eigen::Matrix3d>(curvature_.data() + 9 * k) = rotation_curvature(Rk, Gk);
        double energy = 0.0;
        for (Index e = el_.offsets[k]; e < el_.offsets[k + 1]; ++e) {
          const Eigen::Vector3d re = Rk * st_.rest_edge.col(e);
          energy += 0.5 * el_.weight[e] * (XT_.col(el_.edge_i[e]) - XT_.col(el_.edge_j[e]) - re).squaredNorm();
          t_.col(e) = el_.weight[e] * re;
        }
        element_energy_(k) = energy;
      }
      return element_energy_.sum();
    }
    const Eigen::Map<const Eigen::VectorXd> xv(X.data(), 3 * n_);
    Eigen::VectorXd coeff;
    if (st_.options.cluster_fit == ClusterRotationFit::Exact) {
      Eigen::VectorXd uq(3 * n_ + 4 * r_);
      uq << xv, Q;
      coeff = st_.D.transpose() * uq;
    } else {
      coeff = st_.DV.transpose() * xv;
    }
    for (Index i = 0; i < m_.d; ++i)
      Eigen::Map<Eigen::Matrix3d>(R.data() + 9 * i) = fit_rotation(Eigen::Map<const Eigen::Matrix3d>(coeff.data() + 9 * i));
    return energy();
  }

  // E′ of the current pose (rotations at identity before a local step).
  double rest_rotations_energy() {
    for (Index i = 0; i < m_.d; ++i) Eigen::Map<Eigen::Matrix3d>(R.data() + 9 * i).setIdentity();
    return energy();
  }

  // Global step: K u_f + Afᵀλ = q_f − Hfp u_p, Af u_f = b_g (augmented, see
  // set_handles); updates X (and Q for E′) and returns the largest vertex move.
  double global_step(const ConstrainedValues& cv) {
    linear_term();
    qu_ = st_.P.transpose() * qV_;
    for (Index row = 0; row < st_.nu; ++row)
      if (st_.free_index[row] >= 0) rhs_(st_.free_index[row], 0) = qu_(row);
    rhs_.col(0) -= cv.rhs_pinned;
    if (cv.bg.size() > 0) rhs_.col(0) += st_.rho * (st_.Af.transpose() * cv.bg);
    st_.factor->solveInPlace(rhs_, 1);
    if (cv.bg.size() > 0) {
      const Eigen::VectorXd mu = st_.schur.solve(st_.Af * rhs_.col(0) - cv.bg);
      rhs_.col(0) -= st_.G * mu;
    }
    for (Index row = 0; row < st_.nu; ++row)
      u_(row) = st_.free_index[row] >= 0 ? rhs_(st_.free_index[row], 0) : 0.0;
    for (size_t k = 0; k < st_.pinned_rows.size(); ++k) u_(st_.pinned_rows[k]) = cv.up(static_cast<Index>(k));
    const Eigen::VectorXd xv = st_.P * u_;
    const Eigen::Map<const Vertices> Xnew(xv.data(), n_, 3);
    const double step = (Xnew - X).rowwise().norm().maxCoeff();
    X = Xnew;
    if (!classic_) Q = st_.LQQ.solve(st_.DQ * R - st_.LQV * xv);
    return step;
  }

  // Newton steps (classic energy, no general rows): from here on every
  // local step also keeps, per element, the inverse curvature of its
  // rotation fit (rotation_curvature), which hessian_vector needs.
  void keep_curvature() {
    keep_curvature_ = true;
    curvature_.resize(9 * r_);
    dx_.resize(3 * n_);
    dt_.resize(3, st_.rest_edge.cols());
    dq_.resize(3 * n_);
  }
  // The control-row vector u of the last global step (pinned rows at their
  // targets) and its free part.
  Eigen::VectorXd free_part() const {
    Eigen::VectorXd uf(rhs_.rows());
    for (Index row = 0; row < st_.nu; ++row)
      if (st_.free_index[row] >= 0) uf(st_.free_index[row]) = u_(row);
    return uf;
  }
  // Sets the free rows of u to uf (pinned rows unchanged) and X = P·u; the
  // rotations are those of the last local step until the next.
  void set_free_part(const Eigen::VectorXd& uf) {
    for (Index row = 0; row < st_.nu; ++row)
      if (st_.free_index[row] >= 0) u_(row) = uf(st_.free_index[row]);
    const Eigen::VectorXd xv = st_.P * u_;
    X = Eigen::Map<const Vertices>(xv.data(), n_, 3);
  }
  // ∇E over the free rows at the pose of the last local step:
  // g = (H_u·u − Pᵀq(R))_free.
  void gradient(Eigen::VectorXd* g) {
    linear_term();
    qu_ = st_.Hu * u_ - st_.P.transpose() * qV_;
    g->resize(rhs_.rows());
    for (Index row = 0; row < st_.nu; ++row)
      if (st_.free_index[row] >= 0) (*g)(st_.free_index[row]) = qu_(row);
  }
  // The Hessian of the classic energy E(V) = min_R Σ ½c‖e′ − R e‖² times a
  // free-row vector v (docs/deform.md, "The Newton finish"):
  // H·v = H_u·v − Pᵀ·q(dR), dR_k = R_k[ω_k]×, ω_k = M_k⁻¹·axial(R_kᵀdG_k − dG_kᵀR_k),
  // dG_k = Σ c·(v_i − v_j)eᵀ, at the pose of the last local step.
  void hessian_vector(const Eigen::VectorXd& vf, Eigen::VectorXd* out) {
    Eigen::VectorXd vu = Eigen::VectorXd::Zero(st_.nu);
    for (Index row = 0; row < st_.nu; ++row)
      if (st_.free_index[row] >= 0) vu(row) = vf(st_.free_index[row]);
    dx_ = st_.P * vu;
#pragma omp parallel for schedule(static) num_threads(threads_) if (threads_ > 1 && r_ >= 2048)
    for (Index k = 0; k < r_; ++k) {
      Eigen::Matrix3d dG = Eigen::Matrix3d::Zero();
      for (Index e = el_.offsets[k]; e < el_.offsets[k + 1]; ++e)
        dG.noalias() += (el_.weight[e] * (dx_.segment<3>(3 * el_.edge_i[e]) - dx_.segment<3>(3 * el_.edge_j[e]))) *
                        st_.rest_edge.col(e).transpose();
      const Eigen::Map<const Eigen::Matrix3d> Rk(R.data() + 9 * k);
      const Eigen::Matrix3d W = Rk.transpose() * dG;
      const Eigen::Vector3d w(W(2, 1) - W(1, 2), W(0, 2) - W(2, 0), W(1, 0) - W(0, 1));
      const Eigen::Vector3d om = Eigen::Map<const Eigen::Matrix3d>(curvature_.data() + 9 * k) * w;
      Eigen::Matrix3d skew;
      skew << 0.0, -om(2), om(1), om(2), 0.0, -om(0), -om(1), om(0), 0.0;
      const Eigen::Matrix3d dR = Rk * skew;
      for (Index e = el_.offsets[k]; e < el_.offsets[k + 1]; ++e) dt_.col(e) = el_.weight[e] * (dR * st_.rest_edge.col(e));
    }
    gather(dt_, &dq_);
    const Eigen::VectorXd hv = st_.Hu * vu - st_.P.transpose() * dq_;
    out->resize(vf.size());
    for (Index row = 0; row < st_.nu; ++row)
      if (st_.free_index[row] >= 0) (*out)(st_.free_index[row]) = hv(row);
  }
  // RMS over the vertices of P·v (v over the free rows).
  double vertex_rms(const Eigen::VectorXd& vf) {
    Eigen::VectorXd vu = Eigen::VectorXd::Zero(st_.nu);
    for (Index row = 0; row < st_.nu; ++row)
      if (st_.free_index[row] >= 0) vu(row) = vf(st_.free_index[row]);
    dx_ = st_.P * vu;
    return dx_.norm() / std::sqrt(static_cast<double>(std::max<Index>(n_, 1)));
  }

 private:
  // M_k⁻¹ for the derivative of the rotation fit R_k = polar(G_k): with
  // Y = R_kᵀG_k (symmetric at the fit; also for planar elements, whose G_k
  // has rank 2 and whose fit is the same rotation), M = tr(Y)·I − Y. Eigenvalues
  // of M at or below 1e-12 of its largest are dropped (a fit with no
  // curvature there: the step sees no rotation change).
  static Eigen::Matrix3d rotation_curvature(const Eigen::Matrix3d& Rk, const Eigen::Matrix3d& Gk) {
    Eigen::Matrix3d Y = Rk.transpose() * Gk;
    Y = 0.5 * (Y + Y.transpose()).eval();
    const Eigen::Matrix3d M = Y.trace() * Eigen::Matrix3d::Identity() - Y;
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig;
    eig.computeDirect(M);
    const Eigen::Vector3d lam = eig.eigenvalues();
    const double top = lam.cwiseAbs().maxCoeff();
    Eigen::Vector3d inv;
    for (int i = 0; i < 3; ++i) inv(i) = std::abs(lam(i)) > 1e-12 * top ? 1.0 / lam(i) : 0.0;
    return eig.eigenvectors() * inv.asDiagonal() * eig.eigenvectors().transpose();
  }
  // Σ over the edges at each vertex of ±t_e (+ where it is edge_i).
  void gather(const Eigen::Matrix<double, 3, Eigen::Dynamic>& t, Eigen::VectorXd* q) const {
    const std::vector<Index>& offsets = st_.incident_offsets;
    const std::vector<Index>& edges = st_.incident_edges;
#pragma omp parallel for schedule(static) num_threads(threads_) if (threads_ > 1 && n_ >= 2048)
    for (Index v = 0; v < n_; ++v) {
      Eigen::Vector3d sum = Eigen::Vector3d::Zero();
      for (Index a = offsets[v]; a < offsets[v + 1]; ++a) {
        const Index e = edges[a];
        if (e > 0) sum += t.col(e - 1);
        else sum -= t.col(-e - 1);
      }
      q->segment<3>(3 * v) = sum;
    }
  }
  double energy() const { return modified_arap_energy(m_.V, el_, m_.clusters, m_.parameters, X, Q, R); }
  // q_V: D_s·S (E′), or Σ c·R_k·e per edge end (classic).
  void linear_term() {
    if (!classic_) {
      qV_ = st_.Ds * R;
      return;
    }
    // Gathered per vertex from the t_e of the last local step (which set R).
    gather(t_, &qV_);
  }

  const LocalGlobalState& st_;
  const PreparedModel& m_;
  const RotationElements& el_;
  const bool classic_;
  const Index n_, r_;
  const int threads_;
  // Classic: X transposed (3 × n, a vertex's coordinates together), t_e
  // (3 × E) and the element energies (r) of the last local step.
  Eigen::Matrix<double, 3, Eigen::Dynamic> XT_, t_;
  Eigen::VectorXd element_energy_;
  // Newton (keep_curvature): M_k⁻¹ per element (9r), and hessian_vector's
  // work: P·v (3n), the t_e of dR (3 × E), their per-vertex sums (3n).
  bool keep_curvature_ = false;
  Eigen::VectorXd curvature_, dx_;
  Eigen::Matrix<double, 3, Eigen::Dynamic> dt_;
  Eigen::VectorXd dq_;

 public:
  Vertices X;         // n × 3
  Eigen::VectorXd R;  // classic: 9r; E′: S, 9d
  Eigen::VectorXd Q;  // E′: 4r

 private:
  Eigen::VectorXd qV_, qu_, u_;
  Matrix<double> rhs_;
};

// The rest edges, the edges at each vertex and the planar elements of the
// classic local step (LocalGlobalState).
void classic_local_data(LocalGlobalState* st) {
  const RotationElements& el = st->m.elements;
  const Index E = static_cast<Index>(el.weight.size()), r = el.size();
  st->rest_edge.resize(3, E);
  std::vector<Index> count(static_cast<size_t>(st->n) + 1, 0);
  for (Index e = 0; e < E; ++e) {
    st->rest_edge.col(e) = (st->m.V.row(el.edge_i[e]) - st->m.V.row(el.edge_j[e])).transpose();
    ++count[el.edge_i[e] + 1];
    ++count[el.edge_j[e] + 1];
  }
  for (Index v = 0; v < st->n; ++v) count[v + 1] += count[v];
  st->incident_offsets = count;
  st->incident_edges.resize(static_cast<size_t>(2 * E));
  for (Index e = 0; e < E; ++e) {
    st->incident_edges[count[el.edge_i[e]]++] = e + 1;
    st->incident_edges[count[el.edge_j[e]]++] = -(e + 1);
  }
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
  st.m = detail_reference::prepare_model(normalised(model, st.units), options);
  st.energy_unit = energy_unit(st.units, st.m.tet);
  st.given_elements = in_given_units(st.m.elements, st.units);
  st.frame_targets = detail_reference::targets_model(st.m);
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
  detail_reference::check_handles(st.m, handles);
  detail_reference::check_anchored(st.m, handles);
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
  const SparseMatrix<double> Ks = axis_block(st, K);
  if (Ks.rows() > 0) {
    K = SparseMatrix<double>();  // free it before the factorization
    st.factor = std::make_unique<AxisSeparableFactorization>(separable_factorization(st.options.backend), Ks.rows());
    st.factor->compute(Ks);
  } else {
    st.factor = make_factorization(st.options.backend);
    st.factor->compute(K);
  }
  summary.axis_separable = Ks.rows() > 0;
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

namespace {

// ReferenceSummary::estimated_distance. For a map G with Jacobian J near
// its fixed point z*, the residual r = G(z) − z = (J − I)(z − z*), so
// ‖z − z*‖ ≤ ‖r‖ / σ, σ the smallest singular value of I − J: small where
// local-global is slow (the smooth modes of a flat valley), which is where a
// small step says little. σ is estimated on the span of the last kWindow
// steps Δz_j = z_j − z_{j−1}, for which (I − J)Δz_j ≈ −Δr_j: σ² ≈ the least
// μ with ΔRᵀΔR·c = μ·ΔZᵀΔZ·c (a Rayleigh–Ritz value; the span of the recent
// steps is a Krylov space of J, whose extreme modes it finds within a few
// steps). Vertex parts only, RMS over the vertices, over the diagonal; the
// steps kept in float (2·kWindow·3n numbers), their products summed in double.
class DistanceEstimate {
 public:
  static constexpr int kWindow = 16;
  DistanceEstimate(Index nx, Index n, double diagonal)
      : nx_(nx), scale_(1.0 / (std::sqrt(static_cast<double>(std::max<Index>(n, 1))) * diagonal)) {}
  double update(const Eigen::VectorXd& z, const Eigen::VectorXd& gz) {
    if (z_.size() == 0) {  // the first round: sized once
      z_ = z.head(nx_);
      r_ = gz.head(nx_) - z_;
      dz_.setZero(nx_, kWindow);
      dr_.setZero(nx_, kWindow);
      r_new_.resize(nx_);
      return std::numeric_limits<double>::infinity();
    }
    const int c = count_ % kWindow;
    r_new_ = gz.head(nx_) - z.head(nx_);
    dz_.col(c) = (z.head(nx_) - z_).cast<float>();
    dr_.col(c) = (r_new_ - r_).cast<float>();
    z_ = z.head(nx_);
    r_.swap(r_new_);
    ++count_;
    const int m = std::min(count_, kWindow);
    for (int j = 0; j < m; ++j) {  // the new Gram column
      zz_(c, j) = zz_(j, c) = dot(dz_.col(c), dz_.col(j));
      rr_(c, j) = rr_(j, c) = dot(dr_.col(c), dr_.col(j));
    }
    // Scaled to a unit ΔZᵀΔZ diagonal, with a floor for dependent steps.
    Eigen::MatrixXd B = zz_.topLeftCorner(m, m), A = rr_.topLeftCorner(m, m);
    const Eigen::VectorXd d = B.diagonal().cwiseMax(std::numeric_limits<double>::min()).cwiseSqrt().cwiseInverse();
    B = d.asDiagonal() * B * d.asDiagonal();
    A = d.asDiagonal() * A * d.asDiagonal();
    B.diagonal().array() += 1e-10;
    Eigen::GeneralizedSelfAdjointEigenSolver<Eigen::MatrixXd> eig(A, B, Eigen::EigenvaluesOnly);
    const double sigma = eig.info() == Eigen::Success ? std::sqrt(std::max(eig.eigenvalues()(0), 0.0)) : 0.0;
    const double step = r_.norm() * scale_;
    return step / std::max(sigma, kMinGap);
  }

 private:
  static constexpr double kMinGap = 1e-12;
  template <typename A, typename B>
  static double dot(const A& a, const B& b) {
    double sum = 0.0;
    for (Index i = 0; i < a.size(); ++i) sum += static_cast<double>(a(i)) * static_cast<double>(b(i));
    return sum;
  }
  Index nx_;
  double scale_;
  Eigen::VectorXd z_, r_, r_new_;
  Eigen::MatrixXf dz_, dr_;  // nx × kWindow, ring buffers of Δz and Δr
  Eigen::Matrix<double, kWindow, kWindow> zz_ = Eigen::Matrix<double, kWindow, kWindow>::Zero(),
                                          rr_ = Eigen::Matrix<double, kWindow, kWindow>::Zero();
  int count_ = 0;
};

// One trust-region Newton step on the classic energy over the free rows
// (docs/deform.md, "The Newton finish"): H·d = −g by Steihaug's conjugate
// gradients preconditioned with the global step's factor K, stopped at a
// relative preconditioned residual of kNewtonForcing, at the trust region's
// boundary (or negative curvature, followed to it) or after kNewtonMaxCg
// products; the step is kept when the energy falls by more than 1e-4 of
// the model's prediction, and the radius (in the K-norm) shrinks or grows
// with that ratio. Needs the rotations and curvatures of the current pose
// (a local step with keep_curvature).
struct NewtonStep {
  bool accepted = false;      // the energy fell by the Armijo amount; else the pose is unchanged
  bool full = false;          // accepted inside the region, CG converged, the model's prediction met to 10 %
  bool cancelled = false;     // cancel() held during the solve; the pose is unchanged
  int cg = 0;                 // products with H (and solves with K)
  double energy = 0.0;        // of the accepted pose (the old energy if not accepted)
  double step_rms = 0.0;      // RMS vertex move of the accepted step
  double solved_rms = std::numeric_limits<double>::infinity();  // RMS of the step when CG converged inside the region, kept or not
  double max_move = 0.0;      // largest vertex move of the accepted step
  double gradient_step_rms = 0.0;  // RMS vertex move of the local-global step K⁻¹g at the start
};

constexpr double kNewtonForcing = 1e-6;
constexpr int kNewtonMaxCg = 500;

NewtonStep newton_step(Rounds& rounds, const LocalGlobalState& st, double energy, double* radius, int max_products,
                       const std::function<bool()>& cancel) {
  NewtonStep out;
  out.energy = energy;
  Eigen::VectorXd g;
  rounds.gradient(&g);
  const Index nf = g.size();
  const auto precondition = [&](const Eigen::VectorXd& r, Eigen::VectorXd* z) {
    Matrix<double> b = r;
    st.factor->solveInPlace(b, 1);
    *z = b.col(0);
  };
  // Steihaug's truncated CG in the K-norm ‖d‖²_K = dᵀKd (K the
  // preconditioner, so the first iterate is the local-global step), inside
  // the trust region ‖d‖_K ≤ radius; dᵀKd, dᵀKp and pᵀKp by recurrence.
  Eigen::VectorXd d = Eigen::VectorXd::Zero(nf), r = -g, z, p, Hp;
  precondition(r, &z);
  out.gradient_step_rms = rounds.vertex_rms(z);
  p = z;
  double rz = r.dot(z);
  const double r0 = std::sqrt(std::max(rz, 0.0));
  if (!(r0 > 0.0)) return out;
  if (!std::isfinite(*radius)) *radius = r0;  // the first step: as long as the local-global step
  double dKd = 0.0, dKp = 0.0, pKp = rz, model = 0.0;  // model: gᵀd + ½dᵀHd
  bool converged = false, boundary = false;
  for (int j = 0; j < max_products; ++j) {
    if (cancel && cancel()) {
      out.cancelled = true;
      return out;
    }
    rounds.hessian_vector(p, &Hp);
    ++out.cg;
    const double pHp = p.dot(Hp);
    const double alpha = rz / pHp;
    if (!(pHp > 0.0) || dKd + 2 * alpha * dKp + alpha * alpha * pKp >= *radius * *radius) {
      // To the boundary along p: τ ≥ 0 with ‖d + τp‖_K = radius.
      const double disc = dKp * dKp + pKp * (*radius * *radius - dKd);
      const double tau = (-dKp + std::sqrt(std::max(disc, 0.0))) / pKp;
      d += tau * p;
      model += -tau * rz + 0.5 * tau * tau * pHp;
      boundary = true;
      break;
    }
    d += alpha * p;
    model -= 0.5 * alpha * rz;
    r -= alpha * Hp;
    precondition(r, &z);
    const double rz_next = r.dot(z);
    const double beta = rz_next / rz;
    dKd += 2 * alpha * dKp + alpha * alpha * pKp;
    dKp = beta * (dKp + alpha * pKp);
    pKp = rz_next + beta * beta * pKp;
    p = z + beta * p;
    rz = rz_next;
    if (std::sqrt(std::max(rz, 0.0)) <= kNewtonForcing * r0) {
      converged = true;
      break;
    }
  }
  const double step_norm = std::sqrt(std::max(boundary ? *radius * *radius : dKd, 0.0));
  const double predicted = -model;
  if (!(predicted > 0.0) || !d.allFinite()) {
    *radius = 0.25 * step_norm;
    return out;
  }
  if (converged && !boundary) out.solved_rms = rounds.vertex_rms(d);
  const Eigen::VectorXd u0 = rounds.free_part();
  const Vertices X0 = rounds.X;
  rounds.set_free_part(u0 + d);
  const double next = rounds.local_step();
  const double ratio = (energy - next) / predicted;
  if (!(ratio > 1e-4) || !std::isfinite(next) || !rounds.X.allFinite()) {
    *radius = 0.25 * step_norm;
    rounds.set_free_part(u0);  // back, with its rotations
    rounds.local_step();
    return out;
  }
  if (ratio < 0.25) *radius = 0.25 * step_norm;
  else if (ratio > 0.75 && boundary) *radius *= 2.0;
  out.accepted = true;
  // Full: inside the region, the solve converged, and the model predicted
  // the energy's fall to 10 % (where it does not, the valley curves and
  // the step says little about the distance left).
  const double slack = 1e-12 * std::abs(energy);  // round-off of the energies near the minimiser
  out.full = converged && !boundary && std::abs((energy - next) - predicted) <= 0.1 * predicted + slack;
  out.energy = next;
  out.step_rms = rounds.vertex_rms(d);
  out.max_move = (rounds.X - X0).rowwise().norm().maxCoeff();
  return out;
}

// LocalGlobalArap::solve in the units-free frame: targets and `initial`
// (checked; empty: the rest pose) are in it, and so is what it returns.
ReferenceSummary run_rounds(const LocalGlobalState& st, const HandleTargets& targets, ReferenceSolution* out,
                            const Vertices& initial, const std::function<bool()>& cancel) {
  const PreparedModel& m = st.m;
  const bool classic = st.options.energy == ReferenceEnergy::ClassicArap;
  const Eigen::Matrix3d frame = classic ? Eigen::Matrix3d::Identity() : st.options.frame;
  const Eigen::Matrix3d Ft = frame.transpose();

  const Timer timer;
  ReferenceSummary summary;
  summary.energy_kind = st.options.energy;
  const ConstrainedValues cv = constrained_values(st, targets, frame);
  // Pose and rotations in the solve frame; those of the initial pose (the
  // identities at rest).
  Rounds rounds(st, classic, initial.size() > 0 ? Vertices(initial * frame) : m.V);  // rows: (Fᵀ v)ᵀ = vᵀF
  summary.initial_energy = classic || initial.size() > 0 ? rounds.local_step() : rounds.rest_rotations_energy();
  double energy = summary.initial_energy;
  summary.status = Status::Success;
  // The fixed-point iterate z = [vec V′; Q] (reference.h) and its image G(z).
  const Index nx = 3 * st.n;
  Eigen::VectorXd z(nx + rounds.Q.size()), gz(z.size()), za(z.size());
  const auto pack = [&](Eigen::VectorXd* v) {
    v->head(nx) = Eigen::Map<const Eigen::VectorXd>(rounds.X.data(), nx);
    v->tail(rounds.Q.size()) = rounds.Q;
  };
  const auto unpack = [&](const Eigen::VectorXd& v) {
    Eigen::Map<Eigen::VectorXd>(rounds.X.data(), nx) = v.head(nx);
    rounds.Q = v.tail(rounds.Q.size());
  };
  pack(&z);
  DistanceEstimate distance(nx, st.n, m.diagonal);
  constexpr int kHoldRounds = 16;
  int held_from = -1;  // the first round of the current run of estimates within distance_tolerance
  const bool accelerate = st.options.anderson_window > 0;
  // Newton steps after newton_after rounds: classic energy, no weighted
  // point rows (their Schur solve is not in the preconditioner).
  const bool newton_possible = classic && st.options.newton_after > 0 && st.Af.rows() == 0;
  bool newton_ready = false;
  double previous_newton_step = std::numeric_limits<double>::infinity();  // RMS of the last full Newton step
  double trust_radius = std::numeric_limits<double>::infinity();          // of the Newton steps, in the K-norm
  SafeguardedAnderson anderson;
  if (accelerate) anderson.reset(z.size(), AndersonOptions{st.options.anderson_window});
  // Records a round's (or Newton step's) energy and time; returns the
  // reference test (step and energy change) and the refine test (energy
  // change or fixed-point residual), on summary.last_step and
  // summary.fixed_point_residual as the caller set them.
  const auto end_round = [&](double next) {
    const double drop = std::abs(energy - next) / std::max(std::abs(next), 1e-300);
    energy = next;
    summary.round_energy.push_back(energy);
    summary.round_seconds.push_back(timer.seconds());
    const bool reference_test =
        summary.last_step <= st.options.step_tolerance * m.diagonal && drop <= st.options.energy_tolerance;
    const bool refine_test = st.options.tolerance > 0 &&
                             (drop <= st.options.tolerance || summary.fixed_point_residual <= st.options.tolerance);
    return std::pair<bool, bool>{reference_test, refine_test};
  };
  int it = 0;
  for (; it < st.options.max_iterations; ++it) {
    if (cancel && cancel()) {
      summary.cancelled = true;
      break;
    }
    if (newton_ready) {
      // max_iterations bounds the work: rounds and Hessian products (each a
      // solve with K, about a round) together.
      const int budget = st.options.max_iterations - it - summary.cg_iterations;
      if (budget <= 0) break;
      const NewtonStep step = newton_step(rounds, st, energy, &trust_radius, std::min(kNewtonMaxCg, budget), cancel);
      ++summary.newton_steps;
      summary.cg_iterations += step.cg;
      if (step.cancelled) {
        summary.cancelled = true;
        break;
      }
      double next = step.energy;
      summary.last_step = step.max_move;
      if (!step.accepted) {  // the plain round, which never raises the energy
        ++summary.newton_fallbacks;
        summary.last_step = rounds.global_step(cv);
        next = rounds.local_step();
      }
      summary.fixed_point_residual = step.gradient_step_rms * std::sqrt(static_cast<double>(st.n)) /
                                     std::max(rounds.X.norm(), std::numeric_limits<double>::min());
      // The distance left after full steps s_{k−1}, s_k of converged CG
      // solves that contract, ρ = |s_k| / |s_{k−1}| < 1: |s_k|·ρ / (1 − ρ)
      // (a linear rate; Newton's is faster). One step alone says nothing:
      // early in a flat valley CG's residual test is met by the fast modes
      // while the slow one is still far off.
      const double ratio = step.step_rms / previous_newton_step;
      summary.estimated_distance = step.full && std::isfinite(previous_newton_step) && ratio < 1.0
                                       ? step.step_rms * ratio / (1.0 - ratio) / m.diagonal
                                       : std::numeric_limits<double>::infinity();
      previous_newton_step = step.full ? step.step_rms : std::numeric_limits<double>::infinity();
      const auto [reference_test, refine_test] = end_round(next);
      const bool distance_test =
          st.options.distance_tolerance > 0 && summary.estimated_distance <= st.options.distance_tolerance;
      // The reference test (a move below 1e-10 of the diagonal, the energy
      // still to 1e-13) after a Newton solve that converged: the distance
      // left is about that solve's step, kept or refused at round-off.
      if (reference_test && !std::isfinite(summary.estimated_distance))
        summary.estimated_distance = step.solved_rms / m.diagonal;
      if (reference_test || refine_test || distance_test) {
        summary.converged = true;
        ++it;
        break;
      }
      continue;
    }
    if (newton_possible && it >= st.options.newton_after) {
      // The switch: one plain round, whose local step keeps the curvatures
      // and whose global step sets the control rows the Newton steps move.
      rounds.keep_curvature();
      newton_ready = true;
    }
    summary.last_step = rounds.global_step(cv);  // (V′, Q) = G(z)
    if (!rounds.X.allFinite() || !rounds.Q.allFinite()) {
      unpack(z);  // back to the last accepted pose
      rounds.local_step();
      summary.status = Status::NumericalFailure;
      summary.message = fmt::format("non-finite positions in round {}; returned the pose of round {}", it + 1, it);
      break;
    }
    pack(&gz);
    summary.fixed_point_residual = (gz - z).norm() / std::max(z.norm(), std::numeric_limits<double>::min());
    summary.estimated_distance = distance.update(z, gz);
    double next = 0.0;
    if (newton_ready) {  // the switching round: plain
      next = rounds.local_step();
      z.swap(gz);
    } else if (accelerate && anderson.history() > 0) {
      anderson.propose(z, gz, za);
      unpack(za);
      next = rounds.local_step();
      if (anderson.accept(std::isfinite(next) && rounds.X.allFinite() ? next : std::numeric_limits<double>::quiet_NaN(),
                         energy)) {
        z.swap(za);
      } else {  // the safeguard: the plain round, which never raises the energy
        unpack(gz);
        next = rounds.local_step();
        z.swap(gz);
      }
    } else {
      // The first steps after a start or a refusal are G(z): they fill the
      // history (the extrapolation of the step that makes it 1 is not tried).
      if (accelerate) anderson.propose(z, gz, za);
      next = rounds.local_step();
      z.swap(gz);
    }
    const auto [reference_test, refine_test] = end_round(next);
    // At the reference test the steps are at round-off, where the
    // estimate's Rayleigh quotient is noise: the distance left is about the
    // last move (as after a converged Newton solve above).
    if (reference_test) summary.estimated_distance = summary.last_step / m.diagonal;
    // The distance test holds once the estimate has stayed within the
    // tolerance for half the rounds so far (at least kHoldRounds): early on
    // the fast modes' progress can hide a slow one from the estimate.
    held_from = summary.estimated_distance <= st.options.distance_tolerance ? (held_from < 0 ? it : held_from) : -1;
    const bool distance_test = st.options.distance_tolerance > 0 && held_from >= 0 &&
                               it - held_from + 1 >= std::max(kHoldRounds, (it + 1) / 2);
    if (reference_test || refine_test || distance_test) {
      summary.converged = true;
      ++it;
      break;
    }
  }
  summary.iterations = it;
  summary.rejected_steps = anderson.rejected();
  summary.solve_seconds = timer.seconds();
  // Back to the world frame.
  out->V = rounds.X * Ft;  // rows: (F x)ᵀ = xᵀFᵀ
  out->Q = rounds.Q;
  out->rotations = rounds.R;
  if (!classic) detail_reference::rotations_to_world(frame, &out->rotations);
  summary.energy = energy;  // of the returned (V′, R) or (V′, Q, S)
  summary.handle_residual = handle_residual(st.frame_targets, st.handles, targets, out->V);
  if (summary.status == Status::Success && summary.cancelled) {
    summary.message = fmt::format("cancelled after {} rounds", it);
  } else if (summary.status == Status::Success && !summary.converged) {
    summary.message = fmt::format("iteration limit ({}) reached; last step {:.3e} of the bounding-box diagonal",
                                  st.options.max_iterations, summary.last_step / m.diagonal);
  } else if (summary.status == Status::Success) {
    summary.message = fmt::format("converged in {} rounds", it);
  }
  return summary;
}

}  // namespace

ReferenceSummary LocalGlobalArap::solve(const HandleTargets& targets, ReferenceSolution* out, const Vertices& initial,
                                        const std::function<bool()>& cancel) {
  const State& st = *state_;
  if (!st.has_handles) throw std::invalid_argument("LocalGlobalArap::solve: call precompute and set_handles first");
  if (out == nullptr) throw std::invalid_argument("LocalGlobalArap::solve: out is null");
  detail_reference::check_targets(st.handles, targets);
  if (initial.size() > 0) {
    ::qpreduce::check_size("LocalGlobalArap::solve: initial guess rows", st.n, initial.rows());
    ::qpreduce::check_finite("LocalGlobalArap::solve: initial guess", initial);
  }
  const Normalization& f = st.units;
  vertex_targets(st.given_targets, st.handles, targets, 1e-9 * f.scale);  // throws on conflicts, in the given units
  ReferenceSummary summary = run_rounds(
      st, normalised(targets, f), out,
      initial.size() > 0 ? Vertices((initial.rowwise() - f.centre.transpose()) / f.scale) : Vertices(), cancel);
  detail_reference::to_given_units(f, st.energy_unit, &summary, out);
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
