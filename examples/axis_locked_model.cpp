// A deformation model added without touching the engine (docs/plugins.md):
// ARAP whose cluster rotations may only turn about one axis (here z), e.g.
// for in-plane edits of a height field or a turntable-like twist.
//
// It reuses the ARAP energy blocks (make_arap_model(...)->assemble) and
// supplies its own Phase 2: per cluster, the rotation about z maximising
// tr(RᵀG_a), R(θ) = [[c, −s, 0], [s, c, 0], [0, 0, 1]], which is
// θ = atan2(G₁₀ − G₀₁, G₀₀ + G₁₁) in closed form. It then runs the invariant kit
// (qpreduce/testing) on its blocks and projection, twists a capped cylinder
// with it, and checks every cluster turned about z only.
//
// Usage: axis_locked_model   (exit status 0 when every check holds)
#include <qpreduce/deform/deformer/deformer.h>
#include <qpreduce/deform/energy/model.h>
#include <qpreduce/deform/mesh/shapes.h>
#include <qpreduce/testing/invariants.h>

#include <Eigen/Geometry>
#include <fmt/format.h>

#include <cmath>

using namespace qpreduce;
using namespace qpreduce::deform;

namespace {

// Phase 2: y ← per-cluster rotation about z nearest to G_a.
class AxisLockedProjection final : public ClusterProjection {
 public:
  explicit AxisLockedProjection(Index d) : d_(d) {}

  double project(const Eigen::Ref<const Vector<double>>& g, Eigen::Ref<Vector<double>> y) override {
    double change2 = 0.0;
    for (Index a = 0; a < d_; ++a) {
      const Eigen::Map<const Eigen::Matrix3d> G(g.data() + 9 * a);
      const Eigen::Matrix3d R = about_z(std::atan2(G(1, 0) - G(0, 1), G(0, 0) + G(1, 1)));
      Eigen::Map<Eigen::Matrix3d> s(y.data() + 9 * a);
      change2 += (R - s).squaredNorm();
      s = R;
    }
    return std::sqrt(change2);
  }
  void retract(Eigen::Ref<Eigen::VectorXd> y) const override {
    for (Index a = 0; a < d_; ++a) {
      Eigen::Map<Eigen::Matrix3d> s(y.data() + 9 * a);
      s = about_z(std::atan2(s(1, 0) - s(0, 1), s(0, 0) + s(1, 1)));  // nearest in Frobenius norm
    }
  }
  bool valid(const Eigen::Ref<const Eigen::VectorXd>& y, double tolerance, std::string* why) const override {
    for (Index a = 0; a < d_; ++a) {
      const Eigen::Map<const Eigen::Matrix3d> s(y.data() + 9 * a);
      const double off = (s - about_z(std::atan2(s(1, 0), s(0, 0)))).norm();
      if (!(off <= tolerance)) {
        if (why) *why = fmt::format("cluster {} is not a rotation about z (off by {:.3e})", a, off);
        return false;
      }
    }
    return true;
  }
  double energy(const Eigen::Ref<const Eigen::VectorXd>& g, const Eigen::Ref<const Eigen::VectorXd>& y) const override {
    return -g.dot(y);  // −Σ tr(s_aᵀG_a); ‖s_a‖ is constant on rotations
  }

 private:
  static Eigen::Matrix3d about_z(double theta) {
    return Eigen::AngleAxisd(theta, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  }
  Index d_;
};

class AxisLockedModel final : public DeformationModel {
 public:
  explicit AxisLockedModel(const EnergyParameters& energy) : arap_(make_arap_model(energy)) {}
  std::string name() const override { return "axis-locked-z"; }
  std::vector<std::pair<std::string, double>> parameters() const override { return arap_->parameters(); }
  ModifiedArapSystem assemble(const Vertices& V, const RotationElements& el, const std::vector<int>& clusters,
                              Index d) const override {
    return arap_->assemble(V, el, clusters, d);  // the ARAP energy blocks, unchanged
  }
  std::unique_ptr<ClusterProjection> projection(const ClusterGeometry& geometry) const override {
    return std::make_unique<AxisLockedProjection>(geometry.d);
  }

 private:
  std::shared_ptr<const DeformationModel> arap_;
};

bool report(const char* what, const testing::CheckResult& r) {
  fmt::print("  {:<44} {} {}\n", what, r.ok ? "ok  " : "FAIL", r.message);
  return r.ok;
}

}  // namespace

int main() {
  const TriangleMesh mesh = shapes::capped_cylinder(0.5, 3.0, 12, 10);
  const auto model = std::make_shared<AxisLockedModel>(EnergyParameters{});
  bool ok = true;

  // 1. The invariant kit on a small clustering of the mesh.
  fmt::print("invariant kit ({}):\n", model->name());
  const RotationElements el = spokes_and_rims_elements(mesh.V, mesh.F);
  const Index d = 4;
  std::vector<int> clusters(static_cast<size_t>(el.size()));
  for (Index k = 0; k < el.size(); ++k) clusters[k] = static_cast<int>(std::min<Index>(d - 1, mesh.V(k, 2) / 3.0 * d));
  const ModifiedArapSystem sys = model->assemble(mesh.V, el, clusters, d);
  ok &= report("Hessian L symmetric PSD", testing::check_symmetric_psd(sys.L));
  const auto projection = model->projection(cluster_geometry(mesh.V, el, clusters, d));
  ok &= report("projection valid, idempotent, descending", testing::check_projection(*projection, 9 * d));

  // 2. Twist the top ring by 60° about z with the bottom ring fixed.
  DeformableMesh dm;
  dm.V = mesh.V;
  dm.F = mesh.F;
  dm.patch_types = {PatchType::Fixed, PatchType::Rigid};
  dm.patch_of_vertex.assign(static_cast<size_t>(mesh.V.rows()), -1);
  for (Index v = 0; v < 12; ++v) {
    dm.patch_of_vertex[static_cast<size_t>(v)] = 0;
    dm.patch_of_vertex[static_cast<size_t>(9 * 12 + v)] = 1;
  }
  DeformerOptions options;
  options.custom_model = model;
  options.rotational_proxies = 8;
  options.linear_proxies = 10;
  Deformer deformer;
  const PrecomputeSummary pre = deformer.precompute(dm, options);
  if (!pre.ok()) {
    fmt::print("precompute failed: {}\n", pre.message);
    return 1;
  }
  Handles handles;
  handles.patches = {1};
  deformer.set_handles(handles);
  HandleTargets targets;
  targets.points.resize(0, 3);
  Eigen::Matrix<double, 3, 4> T = Eigen::Matrix<double, 3, 4>::Zero();
  Vertices out;
  for (int f = 1; f <= 6; ++f) {
    T.leftCols<3>() = Eigen::AngleAxisd(f * M_PI / 18.0, Eigen::Vector3d::UnitZ()).toRotationMatrix();
    targets.patch_transforms = {T};
    deformer.frame(targets, &out);
  }
  // Every cluster rotation turns about z only (the global rotation, also
  // fitted from them, too).
  double worst = 0.0;
  const Eigen::VectorXd& S = deformer.rotations();
  for (Index a = 0; a < deformer.rotational_proxies(); ++a) {
    const Eigen::Map<const Eigen::Matrix3d> s(S.data() + 9 * a);
    worst = std::max(worst, (s.col(2) - Eigen::Vector3d::UnitZ()).norm());
  }
  const double top_z = out.row(9 * 12).z();
  fmt::print("twist 60°: {} clusters, largest tilt of a cluster's z axis {:.2e}, top ring at z = {:.4f} (rest 3)\n",
             deformer.rotational_proxies(), worst, top_z);
  ok &= worst < 1e-9 && std::abs(top_z - 3.0) < 1e-5;
  fmt::print(ok ? "all checks hold\n" : "a check failed\n");
  return ok ? 0 : 1;
}
