// Private to the reference solvers: the state of a LocalGlobalArap and the
// pieces of its solve (local_global_solve.cpp): the constraint values, the
// rounds' local and global steps, the distance estimate, the Newton steps.
#pragma once

#include "reference_internal.h"
#include "deformer/control_layer.h"

#include <qpreduce/anderson.h>
#include <qpreduce/checks.h>
#include <qpreduce/util/timer.h>

#include <Eigen/Dense>
#include <Eigen/SparseCholesky>

#include <algorithm>
#include <array>
#include <cmath>
#include <functional>
#include <limits>
#include <memory>
#include <utility>
#include <vector>

namespace qpreduce::deform::detail {


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
  // Classic: the rest edges e (3 × E, the elements' edges in order); per
  // element the unit normal n when all its rest edges lie in n⊥
  // (fit_rotation_planar), else zero; and the element–vertex pairs: per
  // element k its distinct vertices v (CSR over r + 1 pair_offsets,
  // pair_vertex) with a_kv = Σ_{e∈k, i_e = v} c_e·e_e − Σ_{e∈k, j_e = v} c_e·e_e
  // (pair_a, 3 × pairs), and by vertex the pairs at it (CSR over n + 1
  // vertex_pair_offsets, vertex_pairs; pair_element the pair's k). Then
  // Σ_e c_e·(d_i − d_j)·e_eᵀ = Σ_v d_v·a_kvᵀ and the vertex sums of
  // ±c_e·M_k·e_e are Σ_k M_k·a_kv: one vertex per pair (about 7 an element)
  // instead of two per edge (about 12).
  Eigen::Matrix<double, 3, Eigen::Dynamic> rest_edge;
  Eigen::Matrix<double, 3, Eigen::Dynamic> plane_normal;
  std::vector<Index> pair_offsets, pair_vertex, pair_element, vertex_pair_offsets, vertex_pairs;
  Eigen::Matrix<double, 3, Eigen::Dynamic> pair_a;
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
  // When the global step separates (axis_block): K = K_s ⊗ I₃ over the
  // free rows, 3i + a the coordinate a of free vertex free_vertex[i].
  SparseMatrix<double> Ks;
  std::vector<Index> free_vertex;
  Matrix<double> G;                             // (K + ρAfᵀAf)⁻¹Afᵀ
  Eigen::LDLT<Eigen::MatrixXd> schur;           // Af·G
  double rho = 0.0;
  bool has_handles = false;

  // Adds the control-layer entries of coordinate (v, a) scaled by `scale` to column `col`.
  void control_row(Index v, int a, double scale, Index col, Triplets* t) const {
    detail::add_control_row(m.patch_of_vertex, m.V, control_of_free, nu - 12 * s, v, a, scale, col, t);
  }
};

// ---- solve

// The constraint values in the solve frame: u_p (pinned rows), and the
// general rows' right-hand side b_g − A_p·u_p; with Hfp·u_p.
struct ConstrainedValues {
  Eigen::VectorXd up, bg, rhs_pinned;
};

ConstrainedValues constrained_values(const LocalGlobalState& st, const HandleTargets& targets,
                                     const Eigen::Matrix3d& frame);

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
      element_energy_.resize(r_);
    }
  }

  // Rotations from the pose X (and Q for E′); returns the energy.
  double local_step() {
    if (classic_) {
      // Per element k: G_k = Σ c e′eᵀ, R_k = argmax tr(RᵀG_k) and its energy
      // ½Σ c‖e′ − R_k e‖² (the global step's linear term: linear_term).
      // Elements in parallel; the energies are summed in element order
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
    dx_.setZero(3 * n_);  // separable: hessian_vector writes the free vertices' rows only
    dR_.resize(9 * r_);
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
    const bool separable = st_.Ks.rows() > 0;  // the free rows are whole free vertices
    Eigen::VectorXd vu;
    if (separable) {  // the other rows stay zero (keep_curvature)
      for (size_t i = 0; i < st_.free_vertex.size(); ++i)
        dx_.segment<3>(3 * st_.free_vertex[i]) = vf.segment<3>(3 * static_cast<Index>(i));
    } else {
      vu = Eigen::VectorXd::Zero(st_.nu);
      for (Index row = 0; row < st_.nu; ++row)
        if (st_.free_index[row] >= 0) vu(row) = vf(st_.free_index[row]);
      dx_ = st_.P * vu;
    }
    // dG_k = Σ_v dx_v·a_kvᵀ over the element's vertices (LocalGlobalState's pairs).
#pragma omp parallel for schedule(static) num_threads(threads_) if (threads_ > 1 && r_ >= 2048)
    for (Index k = 0; k < r_; ++k) {
      Eigen::Matrix3d dG = Eigen::Matrix3d::Zero();
      for (Index p = st_.pair_offsets[k]; p < st_.pair_offsets[k + 1]; ++p)
        dG.noalias() += dx_.segment<3>(3 * st_.pair_vertex[p]) * st_.pair_a.col(p).transpose();
      const Eigen::Map<const Eigen::Matrix3d> Rk(R.data() + 9 * k);
      const Eigen::Matrix3d W = Rk.transpose() * dG;
      const Eigen::Vector3d w(W(2, 1) - W(1, 2), W(0, 2) - W(2, 0), W(1, 0) - W(0, 1));
      const Eigen::Vector3d om = Eigen::Map<const Eigen::Matrix3d>(curvature_.data() + 9 * k) * w;
      Eigen::Matrix3d skew;
      skew << 0.0, -om(2), om(1), om(2), 0.0, -om(0), -om(1), om(0), 0.0;
      Eigen::Map<Eigen::Matrix3d>(dR_.data() + 9 * k) = Rk * skew;
    }
    vertex_sums(dR_, &dq_);
    out->resize(vf.size());
    if (separable) {  // K_s ⊗ I₃ · v − dq at the free vertices
      const Index ns = st_.Ks.rows();
      Eigen::Map<Eigen::Matrix<double, 3, Eigen::Dynamic>> o(out->data(), 3, ns);
      o.noalias() = Eigen::Map<const Eigen::Matrix<double, 3, Eigen::Dynamic>>(vf.data(), 3, ns) * st_.Ks;
      for (Index i = 0; i < ns; ++i) o.col(i) -= dq_.segment<3>(3 * st_.free_vertex[static_cast<size_t>(i)]);
      return;
    }
    const Eigen::VectorXd hv = st_.Hu * vu - st_.P.transpose() * dq_;
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
  // q_v = Σ_k M_k·a_kv over the element–vertex pairs at each vertex (the
  // vertex sums of ±c_e·M_k·e_e, + where v is edge_i), M_k the 3 × 3 blocks
  // of M (9r).
  void vertex_sums(const Eigen::VectorXd& M, Eigen::VectorXd* q) const {
#pragma omp parallel for schedule(static) num_threads(threads_) if (threads_ > 1 && n_ >= 2048)
    for (Index v = 0; v < n_; ++v) {
      Eigen::Vector3d sum = Eigen::Vector3d::Zero();
      for (Index a = st_.vertex_pair_offsets[v]; a < st_.vertex_pair_offsets[v + 1]; ++a) {
        const Index p = st_.vertex_pairs[a];
        sum.noalias() += Eigen::Map<const Eigen::Matrix3d>(M.data() + 9 * st_.pair_element[p]) * st_.pair_a.col(p);
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
    // Per vertex from the rotations of the last local step.
    vertex_sums(R, &qV_);
  }

  const LocalGlobalState& st_;
  const PreparedModel& m_;
  const RotationElements& el_;
  const bool classic_;
  const Index n_, r_;
  const int threads_;
  // Classic: X transposed (3 × n, a vertex's coordinates together) and the
  // element energies (r) of the last local step.
  Eigen::Matrix<double, 3, Eigen::Dynamic> XT_;
  Eigen::VectorXd element_energy_;
  // Newton (keep_curvature): M_k⁻¹ per element (9r), and hessian_vector's
  // work: P·v (3n), dR_k (9r), their per-vertex sums (3n).
  bool keep_curvature_ = false;
  Eigen::VectorXd curvature_, dx_, dR_, dq_;

 public:
  Vertices X;         // n × 3
  Eigen::VectorXd R;  // classic: 9r; E′: S, 9d
  Eigen::VectorXd Q;  // E′: 4r

 private:
  Eigen::VectorXd qV_, qu_, u_;
  Matrix<double> rhs_;
};

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

NewtonStep newton_step(Rounds& rounds, const LocalGlobalState& st, double energy, double* radius, int max_products,
                       const std::function<bool()>& cancel);

// LocalGlobalArap::solve in the units-free frame: targets and `initial`
// (checked; empty: the rest pose) are in it, and so is what it returns.
ReferenceSummary run_rounds(const LocalGlobalState& st, const HandleTargets& targets, ReferenceSolution* out,
                            const Vertices& initial, const std::function<bool()>& cancel);

}  // namespace qpreduce::deform::detail
