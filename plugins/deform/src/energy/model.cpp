// The built-in deformation models of the plugin contract (model.h): ARAP
// (rotations) and conformal-like (scaled rotations), both over the energy E′
// of Eq. 8–11.
#include <qpreduce/checks.h>
#include "qpreduce/deform/energy/model.h"

#include <Eigen/LU>
#include <fmt/format.h>

#include <algorithm>
#include <cmath>

namespace qpreduce::deform {

ClusterGeometry cluster_geometry(const Vertices& V, const RotationElements& el, const std::vector<int>& clusters,
                                 Index d, std::vector<char> rigid) {
  check_size("cluster_geometry: cluster labels", el.size(), static_cast<Index>(clusters.size()));
  if (!rigid.empty()) check_size("cluster_geometry: rigid flags", d, static_cast<Index>(rigid.size()));
  ClusterGeometry g;
  g.d = d;
  g.measure = Eigen::VectorXd::Zero(d);
  g.stiffness = Eigen::VectorXd::Zero(d);
  for (Index k = 0; k < el.size(); ++k) {
    const int a = clusters[k];
    if (a < 0 || a >= d) {
      throw std::invalid_argument(fmt::format("cluster_geometry: element {} has cluster {} outside [0, {})", k, a, d));
    }
    g.measure(a) += el.measure(k);
    for (Index e = el.offsets[k]; e < el.offsets[k + 1]; ++e)
      g.stiffness(a) += el.weight[e] * (V.row(el.edge_i[e]) - V.row(el.edge_j[e])).squaredNorm();
  }
  for (Index a = 0; a < d; ++a) {
    if (!(g.stiffness(a) > 0.0)) {
      throw std::invalid_argument(fmt::format(
          "cluster_geometry: cluster {} has Σ c‖e‖² = {:.3e} ≤ 0 (no edges, or cotangent weights summing to a "
          "non-positive value); its scale and rotation are undetermined",
          a, g.stiffness(a)));
    }
  }
  std::vector<Eigen::Triplet<double>> tw;
  for (const auto& [k, j] : element_neighbours(el)) {
    const int a = clusters[k], b = clusters[j];
    if (a == b) continue;
    const double w = 0.5 * (el.measure(k) + el.measure(j));
    tw.emplace_back(a, b, w);
    tw.emplace_back(b, a, w);
  }
  g.coupling.resize(d, d);
  g.coupling.setFromTriplets(tw.begin(), tw.end());
  g.rigid = rigid.empty() ? std::vector<char>(static_cast<size_t>(d), 0) : std::move(rigid);
  return g;
}

double cluster_rotation_roughness(const ClusterGeometry& g, const Eigen::Ref<const Eigen::VectorXd>& S) {
  check_size("cluster_rotation_roughness: S", 9 * g.d, S.size());
  double rough = 0.0;
  for (Index a = 0; a < g.d; ++a)
    for (SparseMatrix<double>::InnerIterator it(g.coupling, a); it; ++it)
      if (it.row() > a)
        rough += it.value() * (Eigen::Map<const Eigen::Matrix3d>(S.data() + 9 * a) -
                               Eigen::Map<const Eigen::Matrix3d>(S.data() + 9 * it.row()))
                                  .squaredNorm();
  return rough;
}

namespace {

// Phase 2 for rotations (psi_max == 1) and scaled rotations (psi_max > 1):
// per cluster, G̃_a = G_a + 2γ·Σ_b W_ab s_b (Gauss–Seidel: s_b as already
// updated), t_a = nearest rotation of G̃_a, ψ_a = clamp(tr(t_aᵀG̃_a) / (C_a +
// 6γ·Σ_b W_ab), 1/psi_max, psi_max) (ψ_a = 1 for rotations and rigid clusters).
// Each block update minimises the Phase 2 energy in s_a with the others fixed,
// so that energy never increases.
class ScaledRotationProjection final : public ClusterProjection {
 public:
  ScaledRotationProjection(ClusterGeometry geometry, double gamma, double psi_max)
      : g_(std::move(geometry)), gamma_(gamma), psi_max_(psi_max) {
    denominator_ = g_.stiffness;
    proximal_.setZero(g_.d);
    trace_.setZero(g_.d);
    fits_.setZero(9 * g_.d);
    if (gamma_ > 0.0)
      for (Index a = 0; a < g_.d; ++a)
        for (SparseMatrix<double>::InnerIterator it(g_.coupling, a); it; ++it)
          denominator_(a) += 6.0 * gamma_ * it.value();
  }

  double project(const Eigen::Ref<const Vector<double>>& g, Eigen::Ref<Vector<double>> y) override {
    return std::sqrt(update(g, y, 0, g_.d));
  }

  // Without γ the clusters are independent: parallel rounds may split them.
  Index block_size() const override { return gamma_ > 0.0 ? 0 : 9; }
  double project_blocks(const Eigen::Ref<const Vector<double>>& g, Eigen::Ref<Vector<double>> y, Index first,
                        Index last) override {
    return update(g, y, first, last);
  }

  // Each block to its nearest rotation t (fit_rotations: extrapolated
  // rotations are nearly conformal, four at a time), then to the nearest ψ·t
  // in Frobenius norm: ψ = tr(tᵀs)/3, clamped (scaled rotations only).
  void retract(Eigen::Ref<Eigen::VectorXd> y) const override {
    if (psi_max_ <= 1.0) {
      fit_rotations(y.data(), g_.d);
      return;
    }
    fit_rotations(y.data(), g_.d, trace_.data());
    for (Index a = 0; a < g_.d; ++a) {
      if (g_.rigid[static_cast<size_t>(a)]) continue;
      Eigen::Map<Eigen::Matrix3d>(y.data() + 9 * a) *= std::clamp(trace_(a) / 3.0, 1.0 / psi_max_, psi_max_);
    }
  }

  // Constraints on the rotations (point handles): Phase 2 then also pays
  // ½w_a‖s_a‖²_F = (3/2)·w_a·ψ_a², which moves only the scale's denominator
  // (rotations have constant norm).
  Index proximal_block_size() const override { return 9; }
  // Rotations without γ: ½yᵀN_S y = Σ_a ½‖s_a‖²·C_a/3 is constant on SO(3).
  bool rotation_blocks() const override { return psi_max_ <= 1.0 && gamma_ == 0.0; }
  void set_proximal_weights(const Eigen::Ref<const Vector<double>>& weights) override {
    if (weights.size() == 0) {
      proximal_.setZero(g_.d);
    } else {
      check_size("ScaledRotationProjection::set_proximal_weights", g_.d, weights.size());
      proximal_ = weights;
    }
  }

  // ½yᵀN_S y on scaled rotations: Σ_a ½‖s_a‖²_F·C_a/3 + γ·Σ_{a<b} W_ab‖s_a − s_b‖²_F
  // (energy() without the −tr(s_aᵀG_a) terms).
  double quadratic_term(const Eigen::Ref<const Vector<double>>& y) const override {
    double e = 0.0;
    for (Index a = 0; a < g_.d; ++a) {
      const Eigen::Map<const Eigen::Matrix3d> s(y.data() + 9 * a);
      e += 0.5 * s.squaredNorm() * g_.stiffness(a) / 3.0;
    }
    if (gamma_ > 0.0) e += gamma_ * cluster_rotation_roughness(g_, y);
    return e;
  }

  bool valid(const Eigen::Ref<const Eigen::VectorXd>& y, double tolerance, std::string* why) const override {
    for (Index a = 0; a < g_.d; ++a) {
      const Eigen::Map<const Eigen::Matrix3d> s(y.data() + 9 * a);
      const double psi = std::cbrt(s.determinant());
      const bool scaled = psi_max_ > 1.0 && !g_.rigid[static_cast<size_t>(a)];
      auto fail = [&](const std::string& what) {
        if (why) *why = fmt::format("cluster {}: {}", a, what);
        return false;
      };
      if (!(psi > 0.0)) return fail(fmt::format("det = {:.3e} ≤ 0 (a reflection or singular)", s.determinant()));
      if (!scaled && std::abs(psi - 1.0) > tolerance) return fail(fmt::format("det = {} ≠ 1", s.determinant()));
      if (scaled && (psi < 1.0 / psi_max_ - tolerance || psi > psi_max_ + tolerance)) {
        return fail(fmt::format("scale {} outside [{}, {}]", psi, 1.0 / psi_max_, psi_max_));
      }
      const double off = (s.transpose() * s - psi * psi * Eigen::Matrix3d::Identity()).norm();
      if (off > tolerance * psi * psi) return fail(fmt::format("‖sᵀs − ψ²I‖ = {:.3e}: not a scaled rotation", off));
    }
    return true;
  }

  double energy(const Eigen::Ref<const Eigen::VectorXd>& g, const Eigen::Ref<const Eigen::VectorXd>& y) const override {
    double e = 0.0;
    for (Index a = 0; a < g_.d; ++a) {
      const Eigen::Map<const Eigen::Matrix3d> s(y.data() + 9 * a), G(g.data() + 9 * a);
      e += -s.cwiseProduct(G).sum() + 0.5 * s.squaredNorm() * g_.stiffness(a) / 3.0;
      if (gamma_ > 0.0)
        for (SparseMatrix<double>::InnerIterator it(g_.coupling, a); it; ++it)
          if (it.row() > a)
            e += gamma_ * it.value() * (s - Eigen::Map<const Eigen::Matrix3d>(y.data() + 9 * it.row())).squaredNorm();
    }
    return e;
  }

 private:
  // Clusters [first, last) in order (Gauss–Seidel when γ > 0); returns Σ‖Δs_a‖².
  double update(const Eigen::Ref<const Vector<double>>& g, Eigen::Ref<Vector<double>> y, Index first,
                Index last) const {
    double change2 = 0.0;
    // Without γ the blocks are independent: their rotations four at a time,
    // each from its current s_a (fit_rotations_near).
    if (gamma_ == 0.0)
      fit_rotations_near(g.data() + 9 * first, y.data() + 9 * first, fits_.data() + 9 * first, last - first);
    for (Index a = first; a < last; ++a) {
      Eigen::Matrix3d G = Eigen::Map<const Eigen::Matrix3d>(g.data() + 9 * a);
      if (gamma_ > 0.0)
        for (SparseMatrix<double>::InnerIterator it(g_.coupling, a); it; ++it)
          G += 2.0 * gamma_ * it.value() * Eigen::Map<const Eigen::Matrix3d>(y.data() + 9 * it.row());
      const Eigen::Matrix3d t = gamma_ == 0.0 ? Eigen::Matrix3d(Eigen::Map<const Eigen::Matrix3d>(fits_.data() + 9 * a))
                                              : fit_rotation(G);
      double psi = 1.0;
      if (psi_max_ > 1.0 && !g_.rigid[static_cast<size_t>(a)]) {
        psi = std::clamp(t.cwiseProduct(G).sum() / (denominator_(a) + 3.0 * proximal_(a)), 1.0 / psi_max_, psi_max_);
      }
      Eigen::Map<Eigen::Matrix3d> s(y.data() + 9 * a);
      change2 += (psi * t - s).squaredNorm();
      s = psi * t;
    }
    return change2;
  }

  ClusterGeometry g_;
  double gamma_;
  double psi_max_;
  Eigen::VectorXd denominator_;  // C_a + 6γ·Σ_b W_ab
  Eigen::VectorXd proximal_;     // w_a of set_proximal_weights (d): ½w_a‖s_a‖² = (3/2)·w_a·ψ_a²
  mutable Eigen::VectorXd trace_;  // retract's scratch: tr(tᵀs) per cluster (d)
  mutable Eigen::VectorXd fits_;   // update's scratch without γ: t_a (9d; parallel rounds write disjoint blocks)
};

class ArapFamilyModel final : public DeformationModel {
 public:
  ArapFamilyModel(const EnergyParameters& energy, double psi_max) : energy_(energy), psi_max_(psi_max) {
    std::string why;
    if (!energy_.is_valid(&why)) throw std::invalid_argument("EnergyParameters: " + why);
  }
  std::string name() const override { return psi_max_ > 1.0 ? "conformal" : "arap"; }
  std::vector<std::pair<std::string, double>> parameters() const override {
    std::vector<std::pair<std::string, double>> p = {
        {"energy.alpha", energy_.alpha}, {"energy.beta", energy_.beta}, {"energy.gamma", energy_.gamma}};
    if (psi_max_ > 1.0) p.emplace_back("conformal.psi_max", psi_max_);
    return p;
  }
  ModifiedArapSystem assemble(const Vertices& V, const RotationElements& el, const std::vector<int>& clusters,
                              Index d) const override {
    EnergyParameters p = energy_;
    if (!el.is_surface) p.beta = 0.0;  // β acts on surface normals only
    return assemble_modified_arap(V, el, clusters, d, p);
  }
  std::unique_ptr<ClusterProjection> projection(const ClusterGeometry& geometry) const override {
    return std::make_unique<ScaledRotationProjection>(geometry, energy_.gamma, psi_max_);
  }

 private:
  EnergyParameters energy_;
  double psi_max_;
};

}  // namespace

std::shared_ptr<const DeformationModel> make_arap_model(const EnergyParameters& energy) {
  return std::make_shared<ArapFamilyModel>(energy, 1.0);
}

std::shared_ptr<const DeformationModel> make_conformal_model(const EnergyParameters& energy, double psi_max) {
  if (!(psi_max > 1.0) || !std::isfinite(psi_max)) {
    throw std::invalid_argument(fmt::format("conformal model: psi_max must be finite and > 1, got {}", psi_max));
  }
  return std::make_shared<ArapFamilyModel>(energy, psi_max);
}

}  // namespace qpreduce::deform
