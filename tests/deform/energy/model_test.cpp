// The plugin contract (model.h): the built-in models pass the invariant kit
// of qpreduce/testing; conformal-like scaling (Eq. 48–49); the moving-frame
// penalty γ (Eq. 11); a custom model plugged in without touching the engine.
#include <catch2/catch.hpp>

#include "energy_test_util.h"

#include "qpreduce/deform/deformer/deformer.h"
#include "qpreduce/deform/io/io_error.h"
#include "qpreduce/deform/energy/model.h"
#include "qpreduce/deform/mesh/shapes.h"

#include <qpreduce/testing/invariants.h>

#include <Eigen/Dense>

#include <cstdio>
#include <limits>
#include <random>

using namespace qpreduce;
using namespace qpreduce::deform;

namespace {

std::vector<int> band_clusters(const Vertices& V, const RotationElements& el, Index d, int axis) {
  // Clusters as slabs along `axis` (element position: its vertex, or a tet's first edge midpoint).
  const double lo = V.col(axis).minCoeff(), hi = V.col(axis).maxCoeff();
  std::vector<int> c(static_cast<size_t>(el.size()));
  for (Index k = 0; k < el.size(); ++k) {
    const double x = el.is_surface ? V(k, axis)
                                   : 0.5 * (V(el.edge_i[el.offsets[k]], axis) + V(el.edge_j[el.offsets[k]], axis));
    c[k] = static_cast<int>(std::min<Index>(d - 1, static_cast<Index>(d * (x - lo) / (hi - lo + 1e-12))));
  }
  return c;
}

using Case = energy_test::ElementsCase;

// The small box of tets or cylinder surface in 4 slabs along z.
Case small_case(bool tet) {
  Case c = energy_test::small_elements(tet, 4);
  c.clusters = band_clusters(c.V, c.el, c.d, 2);
  return c;
}

// The joint quadratic of E′ in x = [V′ (3n); Q (4r); S (9d)]:
// ½xᵀ[[L, −D], [−Dᵀ, N]]x.
SparseMatrix<double> joint_hessian(const ModifiedArapSystem& sys) {
  const Index nu = sys.L.rows(), ns = sys.N.rows();
  std::vector<Eigen::Triplet<double>> t;
  for (Index c = 0; c < nu; ++c)
    for (SparseMatrix<double>::InnerIterator it(sys.L, c); it; ++it) t.emplace_back(it.row(), c, it.value());
  for (Index c = 0; c < ns; ++c) {
    for (SparseMatrix<double>::InnerIterator it(sys.D, c); it; ++it) {
      t.emplace_back(it.row(), nu + c, -it.value());
      t.emplace_back(nu + c, it.row(), -it.value());
    }
    for (SparseMatrix<double>::InnerIterator it(sys.N, c); it; ++it) t.emplace_back(nu + it.row(), nu + c, it.value());
  }
  SparseMatrix<double> J(nu + ns, nu + ns);
  J.setFromTriplets(t.begin(), t.end());
  return J;
}

// Precomputes `model` with `opts`, sets the handles `h` (both must succeed)
// and moves the one moving patch through four frames, patch_at(a) for
// a = 1/4, 1/2, 3/4, 1, each warm-started from the last. Returns the last
// frame's vertices.
template <typename PatchAt>
Vertices four_patch_frames(Deformer& deformer, const DeformableMesh& model, const DeformerOptions& opts,
                           const Handles& h, PatchAt patch_at) {
  const PrecomputeSummary ps = deformer.precompute(model, opts);
  INFO(ps.message);
  REQUIRE(ps.ok());
  REQUIRE(deformer.set_handles(h).ok());
  Vertices out;
  for (int f = 1; f <= 4; ++f) {
    HandleTargets t;
    t.points.resize(0, 3);
    t.patch_transforms = {patch_at(f / 4.0)};
    deformer.frame(t, &out);
  }
  return out;
}

struct ModelCase {
  const char* label;
  std::shared_ptr<const DeformationModel> model;
};

std::vector<ModelCase> built_in_models() {
  EnergyParameters plain{0.2, 0.3, 0.0}, moving{0.2, 0.3, 0.5};
  return {{"arap", make_arap_model(plain)},
          {"arap + gamma", make_arap_model(moving)},
          {"conformal", make_conformal_model(plain, 1.5)},
          {"conformal + gamma", make_conformal_model(moving, 1.5)}};
}

DeformableMesh bar_model() {
  const TriangleMesh m = shapes::capped_cylinder(0.5, 4.0, 10, 13);
  DeformableMesh model;
  model.V = m.V;
  model.F = m.F;
  return model;
}

// The end rings as two patches (bottom first) prescribed by handles; a
// Fixed bottom patch is always held at rest and is not a handle.
Handles end_patches(DeformableMesh* model, Index around, Index rings, PatchType bottom) {
  model->patch_types = {bottom, PatchType::Affine};
  model->patch_of_vertex.assign(static_cast<size_t>(model->V.rows()), -1);
  for (Index v = 0; v < around; ++v) {
    model->patch_of_vertex[static_cast<size_t>(v)] = 0;
    model->patch_of_vertex[static_cast<size_t>((rings - 1) * around + v)] = 1;
  }
  Handles h;
  if (bottom != PatchType::Fixed) h.patches.push_back(0);
  h.patches.push_back(1);
  return h;
}

// Both end patches scaled by λ about (0, 0, 2).
HandleTargets scaled_targets(double scale) {
  Eigen::Matrix<double, 3, 4> T;
  T.leftCols<3>() = scale * Eigen::Matrix3d::Identity();
  T.col(3) = (1.0 - scale) * Eigen::Vector3d(0, 0, 2.0);
  HandleTargets t;
  t.points.resize(0, 3);
  t.patch_transforms = {T, T};
  return t;
}

// Mean distance of the middle ring's vertices from the axis (rest radius 0.5).
double middle_radius(const Vertices& V, Index around, Index rings) {
  const Index ring = rings / 2;
  double r = 0.0;
  for (Index v = 0; v < around; ++v) r += V.row(ring * around + v).head<2>().norm();
  return r / static_cast<double>(around);
}

}  // namespace

TEST_CASE("every built-in model passes the invariant kit", "[model][kit]") {
  const bool tet = GENERATE(false, true);
  CAPTURE(tet);
  const Case c = small_case(tet);
  const Index n = c.V.rows(), r = c.el.size();
  for (const ModelCase& mc : built_in_models()) {
    CAPTURE(mc.label);
    const ModifiedArapSystem sys = mc.model->assemble(c.V, c.el, c.clusters, c.d);
    REQUIRE(sys.L.rows() == 3 * n + 4 * r);
    REQUIRE(sys.N.rows() == 9 * c.d);
    const SparseMatrix<double> J = joint_hessian(sys);
    const testing::CheckResult psd = testing::check_symmetric_psd(J);
    INFO(psd.message);
    CHECK(psd.ok);
    // The quadratic form is the energy evaluated term by term, E′ = ½xᵀJx exactly.
    EnergyParameters p{0.2, tet ? 0.0 : 0.3, mc.model->parameters()[2].second};
    const auto energy = [&](const Eigen::VectorXd& x) {
      Vertices Vp(n, 3);
      for (Index v = 0; v < n; ++v) Vp.row(v) = x.segment<3>(3 * v).transpose();
      return modified_arap_energy(c.V, c.el, c.clusters, p, Vp, x.segment(3 * n, 4 * r), x.tail(9 * c.d));
    };
    testing::QuadraticOptions qo;
    qo.scale = 0.3;
    const testing::CheckResult quad = testing::check_quadratic_model(energy, J, Eigen::VectorXd::Zero(J.rows()), qo);
    INFO(quad.message);
    CHECK(quad.ok);
    // Phase 2, with one rigid cluster.
    std::vector<char> rigid(static_cast<size_t>(c.d), 0);
    rigid[1] = 1;
    const auto projection = mc.model->projection(cluster_geometry(c.V, c.el, c.clusters, c.d, rigid));
    for (double scale : {0.1, 1.0, 30.0}) {
      testing::ProjectionOptions po;
      po.input_scale = scale;
      po.tolerance = 1e-9;
      const testing::CheckResult proj = testing::check_projection(*projection, 9 * c.d, po);
      INFO("input scale " << scale << ": " << proj.message);
      CHECK(proj.ok);
    }
    // Reflected input: det = +1 (or ψ > 0) and the rigid cluster a rotation.
    Eigen::VectorXd g = Eigen::VectorXd::Zero(9 * c.d), y = g;
    for (Index a = 0; a < c.d; ++a) Eigen::Map<Eigen::Matrix3d>(g.data() + 9 * a) = Eigen::Vector3d(1, 1, -1).asDiagonal();
    projection->project(g, y);
    std::string why;
    CHECK(projection->valid(y, 1e-12, &why));
    INFO(why);
    CHECK(Eigen::Map<const Eigen::Matrix3d>(y.data() + 9).determinant() == Approx(1.0).epsilon(1e-12));
  }
}

TEST_CASE("the kit catches broken energies and projections", "[model][kit]") {
  // An asymmetric and an indefinite H, a wrong gradient, a projection that
  // leaves reflections: each check must fail with a message.
  SparseMatrix<double> A(2, 2);
  A.insert(0, 0) = 1.0;
  A.insert(0, 1) = 0.5;
  CHECK_FALSE(testing::check_symmetric_psd(A).ok);
  SparseMatrix<double> B(2, 2);
  B.insert(0, 0) = 1.0;
  B.insert(1, 1) = -0.1;
  const testing::CheckResult indefinite = testing::check_symmetric_psd(B);
  CHECK_FALSE(indefinite.ok);
  CHECK(indefinite.message.find("not PSD") != std::string::npos);
  SparseMatrix<double> I(2, 2);
  I.setIdentity();
  const auto cubic = [](const Eigen::VectorXd& x) { return 0.5 * x.squaredNorm() + x(0) * x(0) * x(0); };
  CHECK_FALSE(testing::check_quadratic_model(cubic, I, Eigen::VectorXd::Zero(2)).ok);

  struct Identity {  // "projects" onto nothing: reflections pass through
    double project(const Eigen::Ref<const Eigen::VectorXd>& g, Eigen::Ref<Eigen::VectorXd> y) {
      y = g;
      return 0.0;
    }
    void retract(Eigen::Ref<Eigen::VectorXd>) const {}
    bool valid(const Eigen::Ref<const Eigen::VectorXd>& y, double, std::string* why) const {
      const bool ok = Eigen::Map<const Eigen::Matrix3d>(y.data()).determinant() > 0;
      if (!ok && why) *why = "reflection";
      return ok;
    }
    double energy(const Eigen::Ref<const Eigen::VectorXd>&, const Eigen::Ref<const Eigen::VectorXd>&) const {
      return 0.0;
    }
  } identity;
  CHECK_FALSE(testing::check_projection(identity, 9).ok);
}

TEST_CASE("conformal: uniform scaling of the handles scales the mesh uniformly, ARAP stays near-isometric",
          "[model][conformal]") {
  const Index around = 10, rings = 13;
  DeformableMesh model = bar_model();
  const Handles h = end_patches(&model, around, rings, PatchType::Affine);
  const double lambda = 1.3;
  const HandleTargets targets = scaled_targets(lambda);
  const Eigen::RowVector3d centre(0, 0, 2.0);
  const Vertices expected = (model.V.rowwise() - centre) * lambda;

  DeformerOptions opts;
  opts.rotational_proxies = 8;
  opts.linear_proxies = 12;
  opts.iterations = 40;  // 40 rounds a frame, to the fixed point's last digits
  opts.tolerance = 0.0;
  opts.time_budget = 0.0;
  // A stiff α: E′'s linearised corrections q_k = q0·I + [ω]× can absorb an
  // isotropic stretch at the cost α·a_k‖q_k‖² (paper Section 3.1), so at the
  // default α = 0.1 even the full-space E′ minimiser swells the girth to
  // 0.614 here (classic ARAP: 0.500). With α = 10 E′ is close to classic
  // ARAP (full-space E′: 0.511); uniform scaling under the conformal model
  // has q = 0 and is exact for any α.
  opts.energy.alpha = 10.0;
  opts.model = ModelKind::Conformal;
  opts.conformal_bound = 2.0;
  Deformer conformal;
  REQUIRE(conformal.precompute(model, opts).ok());
  REQUIRE(conformal.model()->name() == "conformal");
  REQUIRE(conformal.set_handles(h).ok());
  Vertices out;
  for (int f = 0; f < 3; ++f) conformal.frame(targets, &out);
  const double err = ((out.rowwise() - centre) - expected).rowwise().norm().maxCoeff();
  CHECK(err < 1e-6 * lambda * 4.0);
  const Eigen::VectorXd psi = conformal.cluster_scales();
  CHECK(psi.minCoeff() == Approx(lambda).epsilon(1e-6));
  CHECK(psi.maxCoeff() == Approx(lambda).epsilon(1e-6));
  CHECK(middle_radius(out, around, rings) == Approx(0.5 * lambda).epsilon(1e-6));

  opts.model = ModelKind::Arap;
  Deformer arap;
  REQUIRE(arap.precompute(model, opts).ok());
  REQUIRE(arap.set_handles(h).ok());
  for (int f = 0; f < 3; ++f) arap.frame(targets, &out);
  const Eigen::VectorXd ones = arap.cluster_scales();
  CHECK((ones.array() - 1.0).abs().maxCoeff() < 1e-9);
  // The handles stretch the bar by 30 %, but its girth stays near the rest
  // radius (near-isometric cross-sections), far from the conformal 0.65.
  const double girth = middle_radius(out, around, rings);
  INFO("ARAP middle radius " << girth);
  CHECK(std::abs(girth - 0.5) < 0.25 * std::abs(0.5 * lambda - 0.5));
}

TEST_CASE("conformal: the scale factors clamp at the bounds", "[model][conformal]") {
  const Index around = 10, rings = 13;
  DeformableMesh model = bar_model();
  const Handles h = end_patches(&model, around, rings, PatchType::Affine);
  DeformerOptions opts;
  opts.rotational_proxies = 8;
  opts.linear_proxies = 12;
  opts.iterations = 40;
  opts.time_budget = 0.0;  // the 40 rounds whatever the machine's load
  opts.model = ModelKind::Conformal;
  opts.conformal_bound = 1.25;
  Deformer deformer;
  REQUIRE(deformer.precompute(model, opts).ok());
  REQUIRE(deformer.set_handles(h).ok());
  Vertices out;
  for (double lambda : {2.0, 0.4}) {
    CAPTURE(lambda);
    for (int f = 0; f < 3; ++f) deformer.frame(scaled_targets(lambda), &out);
    const Eigen::VectorXd psi = deformer.cluster_scales();
    CHECK(psi.maxCoeff() <= 1.25 + 1e-12);
    CHECK(psi.minCoeff() >= 0.8 - 1e-12);
    // Every cluster wants λ, beyond the bound: all sit on the bound.
    const double bound = lambda > 1 ? 1.25 : 0.8;
    CHECK((psi.array() - bound).abs().maxCoeff() < 1e-9);
  }
}

TEST_CASE("gamma > 0 reduces the rotation differences between neighbouring clusters on the bending cylinder",
          "[model][gamma]") {
  const TriangleMesh m = shapes::capped_cylinder(0.5, 4.0, 10, 17);
  DeformableMesh model;
  model.V = m.V;
  model.F = m.F;
  const Index around = 10, rings = 17;
  const Handles h = end_patches(&model, around, rings, PatchType::Fixed);
  // Bend into a quarter circle of radius ρ = 4/(π/2) towards +y: the bottom
  // ring stays, the top ring goes to (0, ρ, ρ) turned by −90° about x.
  const double rho = 8.0 / M_PI;
  const Eigen::Matrix3d R = Eigen::AngleAxisd(-M_PI / 2, Eigen::Vector3d::UnitX()).toRotationMatrix();
  const Eigen::Vector3d t = Eigen::Vector3d(0, rho, rho) - R * Eigen::Vector3d(0, 0, 4.0);
  auto roughness = [&](double gamma) {
    DeformerOptions opts;
    opts.rotational_proxies = 12;
    opts.linear_proxies = 16;
    opts.iterations = 30;
    opts.time_budget = 0.0;  // the 30 rounds whatever the machine's load
    opts.energy.gamma = gamma;
    Deformer deformer;
    // The bend over four frames (warm start).
    four_patch_frames(deformer, model, opts, h, [&](double a) {
      Eigen::Matrix<double, 3, 4> T;
      T.leftCols<3>() = Eigen::AngleAxisd(-a * M_PI / 2, Eigen::Vector3d::UnitX()).toRotationMatrix();
      T.col(3) = a * t;
      return T;
    });
    // Σ_{a<b} W_ab‖s_a − s_b‖² over neighbouring clusters.
    const ClusterGeometry g = cluster_geometry(model.V, deformer.elements(), deformer.clusters(),
                                               deformer.rotational_proxies());
    const double rough = cluster_rotation_roughness(g, deformer.rotations());
    return rough;
  };
  const double off = roughness(0.0);
  const double on = roughness(1.0);
  INFO("rotation roughness: gamma 0 → " << off << ", gamma 1 → " << on);
  CHECK(off > 0.0);
  CHECK(on < 0.9 * off);
}

TEST_CASE("a custom model plugs in without touching the engine", "[model][custom]") {
  // A model that wraps ARAP but freezes every cluster at the identity
  // (Phase 2 does nothing): the result is the linear, rotation-free solve.
  struct Frozen final : DeformationModel {
    std::shared_ptr<const DeformationModel> base = make_arap_model({});
    std::string name() const override { return "frozen"; }
    std::vector<std::pair<std::string, double>> parameters() const override { return base->parameters(); }
    ModifiedArapSystem assemble(const Vertices& V, const RotationElements& el, const std::vector<int>& c,
                                Index d) const override {
      return base->assemble(V, el, c, d);
    }
    std::unique_ptr<ClusterProjection> projection(const ClusterGeometry&) const override {
      struct Keep final : ClusterProjection {
        double project(const Eigen::Ref<const Vector<double>>&, Eigen::Ref<Vector<double>>) override { return 0.0; }
        void retract(Eigen::Ref<Eigen::VectorXd>) const override {}
        bool valid(const Eigen::Ref<const Eigen::VectorXd>&, double, std::string*) const override { return true; }
        double energy(const Eigen::Ref<const Eigen::VectorXd>&, const Eigen::Ref<const Eigen::VectorXd>&) const override {
          return 0.0;
        }
      };
      return std::make_unique<Keep>();
    }
  };
  DeformableMesh model = bar_model();
  const Handles h = end_patches(&model, 10, 13, PatchType::Affine);
  DeformerOptions opts;
  opts.rotational_proxies = 6;
  opts.custom_model = std::make_shared<Frozen>();
  Deformer deformer;
  REQUIRE(deformer.precompute(model, opts).ok());
  CHECK(deformer.model()->name() == "frozen");
  REQUIRE(deformer.set_handles(h).ok());
  Vertices out;
  deformer.frame(scaled_targets(1.2), &out);
  const Eigen::VectorXd& S = deformer.rotations();
  for (Index a = 0; a < deformer.rotational_proxies(); ++a)
    CHECK(Eigen::Map<const Eigen::Matrix3d>(S.data() + 9 * a).isIdentity(1e-15));
}

TEST_CASE("conformal and gamma sessions round-trip through the cache, and a model change is refused",
          "[model][cache]") {
  DeformableMesh model = bar_model();
  const Handles h = end_patches(&model, 10, 13, PatchType::Affine);
  DeformerOptions opts;
  opts.rotational_proxies = 6;
  opts.linear_proxies = 10;
  opts.model = ModelKind::Conformal;
  opts.energy.gamma = 0.5;
  Deformer a;
  REQUIRE(a.precompute(model, opts).ok());
  const std::string path = "model_test_cache.bin";
  a.save(path);
  Deformer b;
  REQUIRE(b.load(path, model, opts).ok());
  REQUIRE(a.set_handles(h).ok());
  REQUIRE(b.set_handles(h).ok());
  Vertices va, vb;
  a.frame(scaled_targets(1.2), &va);
  b.frame(scaled_targets(1.2), &vb);
  CHECK((va - vb).cwiseAbs().maxCoeff() < 1e-6);
  DeformerOptions arap = opts;
  arap.model = ModelKind::Arap;
  try {
    b.load(path, model, arap);
    FAIL("a cache of the conformal model loaded as ARAP");
  } catch (const IoError& e) {
    CHECK(std::string(e.what()).find("conformal") != std::string::npos);
  }
  DeformerOptions other_gamma = opts;
  other_gamma.energy.gamma = 0.25;
  CHECK_THROWS_WITH(b.load(path, model, other_gamma), Catch::Contains("energy.gamma"));
  std::remove(path.c_str());
}

TEST_CASE("model options are validated", "[model][errors]") {
  DeformerOptions o;
  o.model = ModelKind::Conformal;
  o.conformal_bound = 1.0;
  std::string why;
  CHECK_FALSE(o.is_valid(&why));
  CHECK(why.find("conformal_bound") != std::string::npos);
  o.conformal_bound = 2.0;
  o.energy.gamma = -1.0;
  CHECK_FALSE(o.is_valid(&why));
  CHECK(why.find("gamma") != std::string::npos);
  CHECK_THROWS_WITH(make_conformal_model({}, 0.5), Catch::Contains("psi_max"));
  const Case c = small_case(false);
  ModifiedArapSystem moving = make_arap_model({0.1, 0.1, 0.5})->assemble(c.V, c.el, c.clusters, c.d);
  CHECK_FALSE(moving.q_separable);
  CHECK_THROWS_WITH(eliminate_rotation_corrections(moving), Catch::Contains("gamma > 0"));
}

TEST_CASE("rigid patches stay rigid and fixed patches do not move, under every model", "[model][patches]") {
  const auto kind = GENERATE(ModelKind::Arap, ModelKind::Conformal);
  CAPTURE(kind == ModelKind::Conformal);
  const Index around = 10, rings = 17;
  const TriangleMesh m = shapes::capped_cylinder(0.5, 4.0, around, rings);
  DeformableMesh model;
  model.V = m.V;
  model.F = m.F;
  Handles h = end_patches(&model, around, rings, PatchType::Fixed);
  // Rings 7–9 form a free Rigid patch (index 2).
  model.patch_types.push_back(PatchType::Rigid);
  for (Index ring = 7; ring <= 9; ++ring)
    for (Index v = 0; v < around; ++v) model.patch_of_vertex[static_cast<size_t>(ring * around + v)] = 2;
  DeformerOptions opts;
  opts.model = kind;
  opts.rotational_proxies = 10;
  opts.linear_proxies = 12;
  // The checks below are about the fixed point (a Rigid patch's transform is
  // a rotation, a Fixed one the identity), so the frames run to convergence:
  // with the exact rotation step (the default) and a free Rigid patch tied to
  // its cluster, the rounds are plain (no acceleration) and 20 a frame left
  // the patch at 0.14 rad of its converged turn.
  opts.iterations = 200;
  opts.tolerance = 1e-9;
  opts.time_budget = 0.0;  // to the tolerance whatever the machine's load (ASan, a busy CI)
  Deformer deformer;
  // Turn the top patch about its centre (0, 0, 4), grow it 15 % and shift it
  // sideways, over a few frames.
  Vertices out = four_patch_frames(deformer, model, opts, h, [](double a) {
    Eigen::Matrix<double, 3, 4> T;
    T.leftCols<3>() = (1.0 + 0.15 * a) * Eigen::AngleAxisd(-a * 1.4, Eigen::Vector3d::UnitX()).toRotationMatrix();
    const Eigen::Vector3d c(0, 0, 4.0);
    T.col(3) = c - T.leftCols<3>() * c + a * Eigen::Vector3d(0.3, 1.5, -0.5);
    return T;
  });
  const double diag = (model.V.colwise().maxCoeff() - model.V.colwise().minCoeff()).norm();
  // Fixed: the identity, and its vertices at rest (float reconstruction).
  const Eigen::Matrix<double, 3, 4> fixed = deformer.patch_transform(0);
  CHECK((fixed - Eigen::Matrix<double, 3, 4>::Identity()).cwiseAbs().maxCoeff() < 1e-9);
  // Rigid: singular values 1 ± 1e-6, det +1, and it did turn.
  const Eigen::Matrix<double, 3, 4> rigid = deformer.patch_transform(2);
  const Eigen::Vector3d sv = Eigen::JacobiSVD<Eigen::Matrix3d>(rigid.leftCols<3>()).singularValues();
  CHECK((sv.array() - 1.0).abs().maxCoeff() < 1e-6);
  CHECK(rigid.leftCols<3>().determinant() > 0);
  const double angle = Eigen::AngleAxisd(Eigen::Matrix3d(rigid.leftCols<3>())).angle();
  INFO("rigid patch turned by " << angle);
  CHECK(angle > 0.2);
  double fixed_err = 0.0, rigid_err = 0.0;
  for (Index v = 0; v < model.V.rows(); ++v) {
    const int p = model.patch_of_vertex[static_cast<size_t>(v)];
    const Eigen::Vector3d rest = model.V.row(v).transpose(), now = out.row(v).transpose();
    if (p == 0) fixed_err = std::max(fixed_err, (now - rest).norm());
    if (p == 2) rigid_err = std::max(rigid_err, (now - (rigid.leftCols<3>() * rest + rigid.col(3))).norm());
  }
  CHECK(fixed_err < 1e-6 * diag);
  CHECK(rigid_err < 1e-6 * diag);
  if (kind == ModelKind::Conformal) {
    // The patch's own cluster is a rotation, whatever ψ the others take.
    const Eigen::VectorXd psi = deformer.cluster_scales();
    CHECK(psi.maxCoeff() > 1.01);  // the 15 % stretch is taken up by scaling elsewhere
  }

  // The same session from a cache, and a prescribed Rigid patch must be a rotation.
  const std::string path = "model_test_rigid.bin";
  deformer.save(path);
  Deformer loaded;
  REQUIRE(loaded.load(path, model, opts).ok());
  std::remove(path.c_str());
  Handles prescribed = h;
  prescribed.patches.push_back(2);
  REQUIRE(loaded.set_handles(prescribed).ok());
  HandleTargets bad;
  bad.points.resize(0, 3);
  Eigen::Matrix<double, 3, 4> T = Eigen::Matrix<double, 3, 4>::Identity();
  bad.patch_transforms = {T, T};
  bad.patch_transforms[1](0, 0) = 1.2;
  CHECK_THROWS_WITH(loaded.frame(bad, &out), Catch::Contains("Rigid"));
  bad.patch_transforms[1](0, 0) = 1.0;
  loaded.frame(bad, &out);
  CHECK((loaded.patch_transform(2) - T).cwiseAbs().maxCoeff() < 1e-9);
}

TEST_CASE("a frame whose rounds produce NaN reports it and keeps the last good pose", "[model][custom][nan]") {
  // ARAP, except that Phase 2 writes NaN while `poison` is set (a model
  // that breaks down): the frame must say so, not throw from the
  // reconstruction, and the next frame must start from the last good pose.
  struct Poisoned final : DeformationModel {
    std::shared_ptr<const DeformationModel> base = make_arap_model({});
    std::shared_ptr<bool> poison = std::make_shared<bool>(false);
    std::string name() const override { return "poisoned"; }
    std::vector<std::pair<std::string, double>> parameters() const override { return base->parameters(); }
    ModifiedArapSystem assemble(const Vertices& V, const RotationElements& el, const std::vector<int>& c,
                                Index d) const override {
      return base->assemble(V, el, c, d);
    }
    std::unique_ptr<ClusterProjection> projection(const ClusterGeometry& g) const override {
      struct Wrap final : ClusterProjection {
        std::unique_ptr<ClusterProjection> inner;
        std::shared_ptr<bool> poison;
        double project(const Eigen::Ref<const Vector<double>>& in, Eigen::Ref<Vector<double>> y) override {
          const double change = inner->project(in, y);
          if (*poison) y.setConstant(std::numeric_limits<double>::quiet_NaN());
          return change;
        }
        void retract(Eigen::Ref<Eigen::VectorXd> y) const override { inner->retract(y); }
        bool valid(const Eigen::Ref<const Eigen::VectorXd>& y, double tol, std::string* why) const override {
          return inner->valid(y, tol, why);
        }
        double energy(const Eigen::Ref<const Eigen::VectorXd>& a, const Eigen::Ref<const Eigen::VectorXd>& y) const override {
          return inner->energy(a, y);
        }
      };
      auto w = std::make_unique<Wrap>();
      w->inner = base->projection(g);
      w->poison = poison;
      return w;
    }
  };
  auto poisoned = std::make_shared<Poisoned>();
  DeformableMesh model = bar_model();
  const Handles h = end_patches(&model, 10, 13, PatchType::Affine);
  DeformerOptions opts;
  opts.rotational_proxies = 6;
  opts.anderson_window = 0;  // plain rounds: every round goes through project()
  opts.custom_model = poisoned;
  Deformer deformer;
  REQUIRE(deformer.precompute(model, opts).ok());
  REQUIRE(deformer.set_handles(h).ok());
  Vertices good;
  REQUIRE(deformer.frame(scaled_targets(1.1), &good).ok());
  REQUIRE(good.allFinite());
  const Eigen::VectorXd S = deformer.rotations();
  const Eigen::VectorXf w = deformer.reduced_coordinates();

  *poisoned->poison = true;
  Vertices out = good;
  FrameSummary bad;
  REQUIRE_NOTHROW(bad = deformer.frame(scaled_targets(1.2), &out));
  CHECK(bad.status == Status::NumericalFailure);
  CHECK_THAT(bad.message, Catch::Contains("NaN") && Catch::Contains("last good"));
  CHECK(out == good);  // not written
  CHECK(deformer.rotations() == S);
  CHECK(deformer.reduced_coordinates() == w);
  Vertices mapped(model.V.rows(), 3);
  REQUIRE_NOTHROW(bad = deformer.frame(scaled_targets(1.2), Eigen::Map<Vertices>(mapped.data(), mapped.rows(), 3)));
  CHECK(bad.status == Status::NumericalFailure);
  CHECK(mapped.isApprox(good, 1e-6));  // the last good pose again

  *poisoned->poison = false;
  Vertices next;
  const FrameSummary ok = deformer.frame(scaled_targets(1.2), &next);
  CHECK(ok.ok());
  CHECK(next.allFinite());
}
