// Full-space references (reference.h): Ceres and local-global agree, the
// reduced deformer approaches the full E′ solution as proxies increase and
// coincides with it when the proxies cover every vertex, bad scenarios throw.
#include <catch2/catch.hpp>

#include "reference_test_util.h"

#include "qpreduce/deform/mesh/geometry.h"
#include "qpreduce/deform/reference/reference.h"
#include "qpreduce/deform/io/scenario.h"
#include "qpreduce/deform/mesh/shapes.h"

#include <Eigen/Geometry>

#include <cmath>
#include <limits>

using namespace qpreduce;
using namespace qpreduce::deform;
using namespace qpreduce::deform::reference_test;

namespace {

void check_rotations(const Eigen::VectorXd& R) {
  for (Index i = 0; i < R.size() / 9; ++i) {
    const Eigen::Map<const Eigen::Matrix3d> Ri(R.data() + 9 * i);
    CHECK((Ri.transpose() * Ri - Eigen::Matrix3d::Identity()).norm() < 1e-9);
    CHECK(Ri.determinant() == Approx(1.0).margin(1e-9));
  }
}

}  // namespace

TEST_CASE("Ceres and local-global references agree at convergence", "[reference]") {
  if (!has_ceres_reference()) {
    WARN("built without Ceres; skipped");
    return;
  }
  const bool tet = GENERATE(false, true);
  const ReferenceEnergy kind = GENERATE(ReferenceEnergy::ClassicArap, ReferenceEnergy::ModifiedArap);
  CAPTURE(tet, to_string(kind));
  const Case c = bend_case(tet, 1.0);
  ReferenceOptions opt;
  opt.energy = kind;
  ReferenceSolution lg, ce;
  const ReferenceSummary slg = solve_local_global(c.model, c.handles, c.targets, opt, &lg);
  const ReferenceSummary sce = solve_ceres_reference(c.model, c.handles, c.targets, opt, &ce);
  INFO(slg.solver_report);
  INFO(sce.message);
  REQUIRE(slg.ok());
  REQUIRE(sce.ok());
  CHECK(slg.converged);
  CHECK(sce.converged);
  const double diag = bounding_box_diagonal(c.model.V);
  CHECK(slg.handle_residual < 1e-10 * diag);
  CHECK(sce.handle_residual < 1e-10 * diag);
  CHECK(std::abs(slg.energy - sce.energy) <= 1e-6 * sce.energy);
  CHECK(max_distance(lg.V, ce.V) < 1e-4 * diag);
  check_rotations(lg.rotations);
  check_rotations(ce.rotations);
  // The reported energy is the energy of the returned pose.
  if (kind == ReferenceEnergy::ClassicArap) {
    const RotationElements el = tet ? tet_elements(c.model.V, c.model.T) : spokes_and_rims_elements(c.model.V, c.model.F);
    CHECK(arap_energy(c.model.V, el, lg.V) == Approx(slg.energy).epsilon(1e-12));
    CHECK(arap_energy(c.model.V, el, ce.V) == Approx(sce.energy).epsilon(1e-12));
  }
}

TEST_CASE("local-global: monotone energy, warm start, frame rotation", "[reference]") {
  const Case c = bend_case(false, 0.8);
  const ReferenceEnergy kind = GENERATE(ReferenceEnergy::ClassicArap, ReferenceEnergy::ModifiedArap);
  CAPTURE(to_string(kind));
  ReferenceOptions opt;
  opt.energy = kind;
  LocalGlobalArap lg;
  lg.precompute(c.model, opt);
  REQUIRE(lg.set_handles(c.handles).ok());
  // Block-coordinate descent: the energy after k rounds never rises with k.
  ReferenceSolution a, b;
  double previous = std::numeric_limits<double>::infinity();
  for (int rounds = 1; rounds <= 20; ++rounds) {
    ReferenceOptions few = opt;
    few.max_iterations = rounds;
    const ReferenceSummary s = solve_local_global(c.model, c.handles, c.targets, few, &a);
    CHECK(s.energy <= previous * (1 + 1e-12));
    previous = s.energy;
  }
  const ReferenceSummary full = lg.solve(c.targets, &a);
  REQUIRE(full.converged);
  CHECK(full.energy <= previous);
  if (kind == ReferenceEnergy::ClassicArap) {
    // Started at its own converged answer, the alternation stops at once
    // (E′ would restart with Q = 0, so only the classic energy is checked).
    const ReferenceSummary again = lg.solve(c.targets, &b, a.V);
    CHECK(again.converged);
    CHECK(again.iterations <= 3);
    CHECK(max_distance(a.V, b.V) < 1e-8);
    return;
  }
  // frame = F minimises E′(FᵀV′, Q, FᵀS): the same as the plain problem with
  // every constraint rotated by Fᵀ (the Fixed patch becomes a patch
  // prescribed to Fᵀ·rest), rotated back by F.
  const Eigen::Matrix3d F = Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  ReferenceOptions framed = opt;
  framed.frame = F;
  ReferenceSolution rs, plain;
  REQUIRE(solve_local_global(c.model, c.handles, c.targets, framed, &rs).converged);
  Case rc = c;
  rc.model.patch_types[0] = PatchType::Affine;
  rc.handles.patches = {0, 1};
  Eigen::Matrix<double, 3, 4> fixed = Eigen::Matrix<double, 3, 4>::Zero();
  fixed.leftCols<3>() = F.transpose();
  rc.targets.patch_transforms = {fixed, F.transpose() * c.targets.patch_transforms[0]};
  framed.frame.setIdentity();
  REQUIRE(solve_local_global(rc.model, rc.handles, rc.targets, framed, &plain).converged);
  CHECK(max_distance(rs.V, plain.V * F.transpose()) < 1e-7);
  CHECK(max_distance(rs.V, a.V) > 1e-4);  // E′ is not rotation invariant
}

TEST_CASE("reduced E' solutions approach the full-space one as linear proxies increase", "[reference]") {
  // Point handles on single vertices: unlike patches (whose 12 parameters are
  // linear proxies themselves, so that a .sel/.def pose lies in the subspace
  // for any proxy count), their rows are not in Span(C) when the proxies are
  // group averages, so the subspace error is real and shrinks with m.
  Case c = bend_case(false, 0.0);
  c.model.patch_types = {PatchType::Fixed};
  for (int& p : c.model.patch_of_vertex)
    if (p == 1) p = -1;
  c.handles = {};
  c.targets = {};
  const Index n = c.model.V.rows();
  const std::vector<Index> picked = {n - 1, 40, 44, 28};  // top centre, two top-ring vertices, one mid-ring
  const Eigen::Matrix3d R = Eigen::AngleAxisd(0.9, Eigen::Vector3d::UnitX()).toRotationMatrix();
  c.targets.points.resize(static_cast<Index>(picked.size()), 3);
  for (size_t h = 0; h < picked.size(); ++h) {
    c.handles.points.push_back({{picked[h]}, {}});
    c.targets.points.row(static_cast<Index>(h)) =
        (R * c.model.V.row(picked[h]).transpose() + Eigen::Vector3d(0.3, -0.8, -0.4)).transpose();
  }
  const double diag = bounding_box_diagonal(c.model.V);
  // The reduced alternation's limit is the fixed point of the same
  // alternation in full space: the E′ minimiser with the exact rotation step,
  // the PaperPhase2 fixed point with the paper's (Eq. 19: Q dropped); the
  // global rotation adaptation is off so that both minimise plain E′.
  ReferenceOptions opt;
  opt.energy = ReferenceEnergy::ModifiedArap;
  opt.cluster_fit = ClusterRotationFit::PaperPhase2;
  ReferenceSolution full;
  REQUIRE(solve_local_global(c.model, c.handles, c.targets, opt, &full).converged);
  opt.cluster_fit = ClusterRotationFit::Exact;
  ReferenceSolution exact;
  REQUIRE(solve_local_global(c.model, c.handles, c.targets, opt, &exact).converged);

  auto reduced = [&](Index proxies, ClusterRotationFit fit) {
    DeformableMesh model = c.model;
    if (proxies < n) {
      ClusterOptions copt;
      REQUIRE(linear_proxies_groups(model.V, model.F, proxies, GroupSpace::Positions, copt, &model.linear).ok());
    } else {
      std::vector<std::vector<Index>> singles;
      for (Index v = 0; v < n; ++v) singles.push_back({v});
      model.linear = linear_proxies_from_groups(singles, n);
    }
    DeformerOptions dopt;
    dopt.global_rotation = false;
    dopt.rotation_fit = fit;
    if (fit != ClusterRotationFit::Exact) dopt.anderson_window = 0;  // plain rounds for the paper's step
    dopt.iterations = 50;
    dopt.time_budget = 0.0;  // the 50 rounds whatever the machine's load
    Deformer deformer;
    REQUIRE(deformer.precompute(model, dopt).ok());
    REQUIRE(deformer.set_handles(c.handles).ok());
    Vertices out;
    for (int frame = 0; frame < 400; ++frame)
      if (deformer.frame(c.targets, &out).last_change < 1e-12) break;
    return out;
  };
  std::vector<double> rms;
  for (Index m : {5, 9, 17, 32}) {
    rms.push_back(rms_distance(reduced(m, ClusterRotationFit::Exact), exact.V) / diag);
    CAPTURE(m, rms.back());
    if (rms.size() > 1) CHECK(rms.back() <= rms[rms.size() - 2] * 1.1 + 1e-6);
  }
  CHECK(rms.back() < 0.5 * rms.front());
  // A proxy at every vertex: the subspace is the whole space; the reduced
  // answer (reconstructed in float) coincides with the full one, for either
  // rotation step.
  CHECK(max_distance(reduced(n, ClusterRotationFit::Exact), exact.V) < 1e-5 * diag);
  CHECK(max_distance(reduced(n, ClusterRotationFit::PaperPhase2), full.V) < 1e-5 * diag);
  // The two E′ fixed points (Eq. 19 vs the exact S-step) differ, by little.
  CHECK(max_distance(full.V, exact.V) < 0.05 * diag);
}

TEST_CASE("references reject bad scenarios with clear errors", "[reference]") {
  const Case c = bend_case(false, 0.5);
  ReferenceOptions opt;
  ReferenceSolution out;
  SECTION("conflicting targets") {
    Case bad = c;
    Index fixed_vertex = 0;
    while (bad.model.patch_of_vertex[fixed_vertex] != 0) ++fixed_vertex;
    bad.handles.points.push_back({{fixed_vertex}, {}});
    bad.targets.points.resize(1, 3);
    bad.targets.points.row(0) = bad.model.V.row(fixed_vertex) + Eigen::RowVector3d(0.5, 0, 0);
    CHECK_THROWS_WITH(solve_local_global(bad.model, bad.handles, bad.targets, opt, &out),
                      Catch::Contains("conflicting targets") && Catch::Contains("Fixed patch 0"));
    if (has_ceres_reference()) {
      CHECK_THROWS_WITH(solve_ceres_reference(bad.model, bad.handles, bad.targets, opt, &out),
                        Catch::Contains("conflicting targets"));
    }
    // The same vertex held where its patch holds it is not a conflict.
    bad.targets.points.row(0) = bad.model.V.row(fixed_vertex);
    CHECK(solve_local_global(bad.model, bad.handles, bad.targets, opt, &out).ok());
  }
  SECTION("a component without anchors") {
    Case bad = c;
    const Index n = c.model.V.rows();
    bad.model.V.resize(2 * n, 3);
    bad.model.V << c.model.V, c.model.V.rowwise() + Eigen::RowVector3d(5, 0, 0);
    bad.model.F.resize(2 * c.model.F.rows(), 3);
    bad.model.F << c.model.F, c.model.F.array() + static_cast<int>(n);
    bad.model.patch_of_vertex.resize(static_cast<size_t>(2 * n), -1);
    CHECK_THROWS_WITH(solve_local_global(bad.model, bad.handles, bad.targets, opt, &out),
                      Catch::Contains("connected component 1") && Catch::Contains("no handle"));
    if (has_ceres_reference()) {
      CHECK_THROWS_WITH(solve_ceres_reference(bad.model, bad.handles, bad.targets, opt, &out),
                        Catch::Contains("connected component 1"));
    }
    // One pinned vertex anchors it.
    bad.handles.points.push_back({{n + 3}, {}});
    bad.targets.points.resize(1, 3);
    bad.targets.points.row(0) = bad.model.V.row(n + 3);
    const ReferenceSummary s = solve_local_global(bad.model, bad.handles, bad.targets, opt, &out);
    CHECK(s.ok());
    CHECK(s.handle_residual < 1e-10);
  }
  SECTION("dependent weighted handles, unsupported constraints for Ceres") {
    Case bad = c;
    bad.handles.points.push_back({{10, 11}, {0.5, 0.5}});
    bad.handles.points.push_back({{10, 11}, {1.0, 1.0}});
    bad.targets.points = Vertices::Zero(2, 3);
    LocalGlobalArap lg;
    lg.precompute(bad.model, opt);
    CHECK_THROWS_WITH(lg.set_handles(bad.handles), Catch::Contains("linearly dependent"));
    if (has_ceres_reference()) {
      CHECK_THROWS_WITH(solve_ceres_reference(bad.model, bad.handles, bad.targets, opt, &out),
                        Catch::Contains("weighted group"));
    }
  }
  SECTION("E' without clusters, wrong target sizes") {
    Case bad = c;
    bad.model.clusters.clear();
    opt.energy = ReferenceEnergy::ModifiedArap;
    CHECK_THROWS_WITH(solve_local_global(bad.model, bad.handles, bad.targets, opt, &out),
                      Catch::Contains("clusters"));
    opt.energy = ReferenceEnergy::ClassicArap;
    bad = c;
    bad.targets.patch_transforms.clear();
    CHECK_THROWS_WITH(solve_local_global(bad.model, bad.handles, bad.targets, opt, &out),
                      Catch::Contains("patch transforms"));
  }
}

TEST_CASE("local-global with weighted point handles matches pinned vertices", "[reference]") {
  // A weighted handle with all weight on one vertex is the same constraint as
  // pinning it: both paths of the global step give the same answer.
  Case c = bend_case(false, 0.6);
  const Index v = 20;
  Case pinned = c, weighted = c;
  pinned.handles.points.push_back({{v}, {}});
  weighted.handles.points.push_back({{v, v + 1}, {1.0, 0.0}});
  const Eigen::RowVector3d target = c.model.V.row(v) + Eigen::RowVector3d(0.2, 0.1, 0.0);
  pinned.targets.points = target;
  weighted.targets.points = target;
  ReferenceOptions opt;
  ReferenceSolution a, b;
  const ReferenceSummary sa = solve_local_global(pinned.model, pinned.handles, pinned.targets, opt, &a);
  const ReferenceSummary sb = solve_local_global(weighted.model, weighted.handles, weighted.targets, opt, &b);
  REQUIRE(sa.converged);
  REQUIRE(sb.converged);
  CHECK(sb.handle_residual < 1e-9);
  CHECK(max_distance(a.V, b.V) < 1e-7);
  CHECK(sa.energy == Approx(sb.energy).epsilon(1e-9));
}

TEST_CASE("local-global: one factor for the three axes, and the thread count, leave the answer as it was",
          "[reference]") {
  // Classic ARAP with whole patches and vertices held separates by axis
  // (K = K_s ⊗ I₃); with a weighted point handle too (its rows act on each
  // axis alone). The per-axis factor by CHOLMOD (supernodal LLT, and the
  // simplicial LDLT that Backend::Auto takes) and by SimplicialLDLT, and
  // the rounds on 1 or 2 threads, reach the same pose: bit for bit across
  // thread counts (element energies are summed in order), to the solver's
  // round-off across factorizations. E′ couples the axes and does not separate.
  Case c = bend_case(false, 0.6);
  c.handles.points.push_back({{20, 21}, {0.5, 0.5}});
  c.targets.points = 0.5 * (c.model.V.row(20) + c.model.V.row(21)) + Eigen::RowVector3d(0.1, 0.05, 0.0);
  auto run = [&](Backend backend, int threads, ReferenceEnergy energy, bool* separable) {
    ReferenceOptions o;
    o.backend = backend;
    o.threads = threads;
    o.energy = energy;
    o.max_iterations = 300;
    LocalGlobalArap lg;
    lg.precompute(c.model, o);
    const HandleSetSummary hs = lg.set_handles(c.handles);
    REQUIRE(hs.ok());
    *separable = hs.axis_separable;
    ReferenceSolution sol;
    REQUIRE(lg.solve(c.targets, &sol).ok());
    return sol.V;
  };
  bool sep1 = false, sep2 = false, sep3 = false, sep_modified = true;
  const Vertices a = run(Backend::Cholmod, 1, ReferenceEnergy::ClassicArap, &sep1);
  const Vertices b = run(Backend::Auto, 1, ReferenceEnergy::ClassicArap, &sep2);
  const Vertices b2 = run(Backend::Auto, 2, ReferenceEnergy::ClassicArap, &sep3);
  bool sep_eigen = false;
  const Vertices e = run(Backend::SimplicialLDLT, 1, ReferenceEnergy::ClassicArap, &sep_eigen);
  CHECK(sep_eigen);
  CHECK(max_distance(b, e) < 1e-9);
  run(Backend::Auto, 1, ReferenceEnergy::ModifiedArap, &sep_modified);
  CHECK(sep1);
  CHECK(sep2);
  CHECK(sep3);
  CHECK_FALSE(sep_modified);
  CHECK(b == b2);
  CHECK(max_distance(a, b) < 1e-9);
}

namespace {

// The reduced deformer run to its fixed point on `c` (global rotation off, so
// that it minimises plain E′): frames of up to 200 rounds until the relative
// fixed-point residual is below 1e-12.
struct Converged {
  Vertices V;
  FrameSummary last;
  int rounds = 0;
};
Converged converge_reduced(const Case& c, DeformerOptions options) {
  options.global_rotation = false;
  options.iterations = 200;
  options.tolerance = 1e-12;
  options.time_budget = 0.0;  // converged whatever the machine's load
  options.float_rounds = false;
  Deformer deformer;
  REQUIRE(deformer.precompute(c.model, options).ok());
  REQUIRE(deformer.set_handles(c.handles, c.constraints).ok());
  Converged out;
  for (int frame = 0; frame < 100; ++frame) {
    out.last = deformer.frame(c.targets, &out.V);
    REQUIRE(out.last.ok());
    out.rounds += out.last.iterations;
    if (out.last.fixed_point_residual < 1e-12) break;
  }
  return out;
}

}  // namespace

TEST_CASE("exact rotation step: with an exact subspace the reduced fixed point is the full-space E' minimiser",
          "[reference][rotation_step]") {
  // A .sel/.def scenario holds only patches, which are columns of C: the
  // subspace contains the full-space global step's answer for every S, so the
  // reduced alternation IS the full-space block-coordinate descent.
  for (const bool tet : {false, true}) {
    CAPTURE(tet);
    const Case c = bend_case(tet, 0.9);
    const double diag = bounding_box_diagonal(c.model.V);
    ReferenceOptions ro;
    ro.energy = ReferenceEnergy::ModifiedArap;
    ro.cluster_fit = ClusterRotationFit::Exact;
    ReferenceSolution full;
    const ReferenceSummary rs = solve_local_global(c.model, c.handles, c.targets, ro, &full);
    REQUIRE(rs.converged);
    DeformerOptions options;
    options.linear_proxies = 6;
    const Converged exact = converge_reduced(c, options);
    CHECK(max_distance(exact.V, full.V) < 1e-5 * diag);
    // The paper's Eq. 19 converges elsewhere, measurably.
    options.rotation_fit = ClusterRotationFit::PaperPhase2;
    options.anderson_window = 0;
    const Converged paper = converge_reduced(c, options);
    CHECK(max_distance(paper.V, full.V) > 1e-4 * diag);
  }
}

TEST_CASE("Anderson-accelerated rounds: same fixed point, fewer rounds, energy never raised, E' value exact",
          "[reference][anderson]") {
  for (const bool tet : {false, true}) {
    CAPTURE(tet);
    const Case c = bend_case(tet, 0.9);
    const double diag = bounding_box_diagonal(c.model.V);
    DeformerOptions options;
    options.linear_proxies = 6;
    options.anderson_window = 0;
    const Converged plain = converge_reduced(c, options);
    options.anderson_window = 5;
    const Converged fast = converge_reduced(c, options);
    CAPTURE(plain.rounds, fast.rounds, fast.last.rejected_steps);
    CHECK(max_distance(plain.V, fast.V) < 1e-6 * diag);
    CHECK(fast.rounds < plain.rounds);
    // The safeguard's energy is E′ itself: at the fixed point it equals the
    // full-space minimiser's E′ (the subspace is exact here).
    ReferenceOptions ro;
    ro.energy = ReferenceEnergy::ModifiedArap;
    ReferenceSolution full;
    const ReferenceSummary rs = solve_local_global(c.model, c.handles, c.targets, ro, &full);
    REQUIRE(rs.converged);
    CHECK(fast.last.model_energy == Approx(rs.energy).epsilon(1e-7));

    // From rest, k accelerated rounds for k = 1, 2, …: the energy of the
    // answer never goes up (patch handles: the plain fallback is monotone).
    Deformer deformer;
    options.global_rotation = false;
    options.float_rounds = false;
    options.cold_start_rounds = 0;  // k rounds from rest, not to the cold-start tolerance
    REQUIRE(deformer.precompute(c.model, options).ok());
    REQUIRE(deformer.set_handles(c.handles).ok());
    double previous = std::numeric_limits<double>::infinity();
    for (int k = 1; k <= 25; ++k) {
      deformer.reset_pose();
      deformer.set_rounds(k);
      const FrameSummary fs = deformer.frame(c.targets, nullptr);
      CAPTURE(k, fs.model_energy, previous);
      CHECK(fs.model_energy <= previous + 1e-9 * std::abs(previous));
      previous = fs.model_energy;
    }
  }
}

TEST_CASE("accelerated rounds with point handles and the conformal model reach the plain fixed point",
          "[reference][anderson]") {
  Case c = bend_case(false, 0.7);
  const Index n = c.model.V.rows();
  c.handles.points.push_back({{n / 2}, {}});
  c.targets.points.resize(1, 3);
  c.targets.points.row(0) = c.model.V.row(n / 2) + Eigen::RowVector3d(0.4, 0.2, 0.0);
  const double diag = bounding_box_diagonal(c.model.V);
  for (const ModelKind kind : {ModelKind::Arap, ModelKind::Conformal}) {
    DeformerOptions options;
    options.linear_proxies = 6;
    options.model = kind;
    options.anderson_window = 0;
    const Converged plain = converge_reduced(c, options);
    options.anderson_window = 4;
    const Converged fast = converge_reduced(c, options);
    CAPTURE(static_cast<int>(kind), plain.rounds, fast.rounds);
    CHECK(max_distance(plain.V, fast.V) < 1e-6 * diag);
    CHECK(std::isfinite(fast.last.model_energy));
  }
}

// The bend case with its patches as they are and 5 point handles at free
// vertices halfway up, pulled off along a smooth field: a stiff set.
Case point_handle_case() {
  Case c = bend_case(false, 0.9);
  const Index n = c.model.V.rows();
  c.handles.points.clear();
  std::vector<Index> picked;
  const double zmax = c.model.V.col(2).maxCoeff();
  for (Index v = 1; v < n && picked.size() < 5; v += 5)  // free vertices only (not in a .sel patch)
    if (c.model.V(v, 2) > 0.2 * zmax && c.model.V(v, 2) < 0.8 * zmax) picked.push_back(v);
  REQUIRE(picked.size() == 5);
  c.targets.points.resize(static_cast<Index>(picked.size()), 3);
  for (size_t i = 0; i < picked.size(); ++i) {
    c.handles.points.push_back({{picked[i]}, {}});
    const Eigen::RowVector3d p = c.model.V.row(picked[i]);
    c.targets.points.row(static_cast<Index>(i)) =
        p + 0.35 * Eigen::RowVector3d(std::sin(3 * p(2)), std::cos(2 * p(0)), 0.5 * p(1));
  }
  return c;
}

TEST_CASE("point handles off the proxies: E' never rises, and rounds and Newton steps reach one fixed point",
          "[reference][anderson][point_handles]") {
  // Point handles at vertices that are not linear proxies: their rows
  // involve the cluster rotations (A_y ≠ 0). The rounds must step on E′ with
  // z following Phase 1 (docs/engine.md, "Constraints on y"); before that
  // fix they converged elsewhere and could blow up (docs/robustness.md,
  // "Soak"). Stiff sets take Newton steps (DeformerOptions::second_order).
  for (const ModelKind kind : {ModelKind::Arap, ModelKind::Conformal}) {
    CAPTURE(static_cast<int>(kind));
    const Case c = point_handle_case();
    const double diag = bounding_box_diagonal(c.model.V);
    DeformerOptions options;
    options.linear_proxies = 16;
    options.model = kind;
    options.global_rotation = false;
    options.float_rounds = false;
    options.cold_start_rounds = 0;  // k steps on every frame below
    Converged newton;
    for (const bool second_order : {false, true}) {
      CAPTURE(second_order);
      options.second_order = second_order;
      Deformer deformer;
      REQUIRE(deformer.precompute(c.model, options).ok());
      const ConstraintSummary cs = deformer.set_handles(c.handles);
      INFO(cs.brief_report());
      REQUIRE(cs.ok());
      double previous = std::numeric_limits<double>::infinity();
      for (int k = 1; k <= 30; ++k) {  // from rest, k rounds or steps: E′ never goes up
        deformer.reset_pose();
        deformer.set_rounds(k);
        const FrameSummary fs = deformer.frame(c.targets, nullptr);
        REQUIRE(fs.ok());
        CAPTURE(k, fs.model_energy, previous, fs.rejected_steps);
        // ARAP takes Newton steps on this stiff set when asked; conformal never.
        CHECK(fs.second_order == (second_order && kind == ModelKind::Arap));
        CHECK(fs.model_energy <= previous + 1e-9 * std::abs(previous));
        previous = fs.model_energy;
      }
      if (second_order) newton = converge_reduced(c, options);
      // cold_start_rounds: the first frame after set_handles runs to
      // cold_start_tolerance (a cold start: the targets jump from rest),
      // the next ones `iterations` rounds or steps (8 here, no early stop).
      DeformerOptions cold = options;
      cold.iterations = 8;
      cold.tolerance = 0.0;
      cold.time_budget = 0.0;
      cold.cold_start_rounds = 4000;
      cold.cold_start_tolerance = 1e-9;
      Deformer d2;
      REQUIRE(d2.precompute(c.model, cold).ok());
      REQUIRE(d2.set_handles(c.handles).ok());
      Vertices first_pose;
      const FrameSummary first = d2.frame(c.targets, &first_pose), second = d2.frame(c.targets, nullptr);
      const bool stiff = second_order && kind == ModelKind::Arap;
      CAPTURE(first.iterations, first.fixed_point_residual);
      CHECK(first.cold_start);
      CHECK_FALSE(second.cold_start);
      CHECK(first.second_order == stiff);
      CHECK(first.iterations > cold.iterations);
      CHECK(first.fixed_point_residual <= 1e-9);
      CHECK(second.iterations == cold.iterations);
      // The first frame ends at the reduced fixed point: the converged pose.
      const Converged converged = converge_reduced(c, options);
      CHECK(max_distance(first_pose, converged.V) < 1e-6 * diag);
    }
    options.second_order = false;
    options.anderson_window = 0;
    const Converged plain = converge_reduced(c, options);
    options.anderson_window = 5;
    const Converged fast = converge_reduced(c, options);
    CAPTURE(plain.rounds, fast.rounds, newton.rounds);
    CHECK(plain.last.fixed_point_residual < 1e-12);
    CHECK(max_distance(plain.V, fast.V) < 1e-6 * diag);
    CHECK(max_distance(plain.V, newton.V) < 1e-6 * diag);
    CHECK(newton.last.model_energy == Approx(fast.last.model_energy).epsilon(1e-9));
  }
}

TEST_CASE("a stiff point-handle set with more than 28 clusters takes Newton steps too", "[reference][point_handles]") {
  // 32 clusters: 9d = 288 > 256, so the fused rounds' automatic form is the
  // factored one, which has no explicit F_y for a Newton step; a stiff set
  // is set explicitly after all (FusedAlternation::kSecondOrderMaxBlocks).
  // Before, such sets ran the damped rounds, which crawl: the quality
  // study's cylinder/rotated .anim with 32 clusters stopped 16 % RMS away.
  Case c = point_handle_case();
  // Phase 1 in the fast path's factored form (as on the .anim scenarios),
  // without which the fused rounds are explicit anyway.
  c.constraints.factored_cost_ratio = 1e-6;
  c.model.clusters.clear();  // 32 automatic clusters instead of the case's 4 slabs
  DeformerOptions options;
  options.linear_proxies = 16;
  options.rotational_proxies = 32;
  options.global_rotation = false;
  options.float_rounds = false;
  options.cold_start_rounds = 0;
  Deformer deformer;
  const PrecomputeSummary ps = deformer.precompute(c.model, options);
  REQUIRE(ps.ok());
  CHECK(ps.rotational_proxies == 32);
  const ConstraintSummary cs = deformer.set_handles(c.handles, c.constraints);
  INFO(cs.brief_report());
  REQUIRE(cs.ok());
  CHECK(cs.fast_path);
  const FrameSummary fs = deformer.frame(c.targets, nullptr);
  REQUIRE(fs.ok());
  CHECK(fs.second_order);
  const Converged newton = converge_reduced(c, options);
  options.second_order = false;
  const Converged rounds = converge_reduced(c, options);
  CAPTURE(newton.rounds, rounds.rounds, newton.last.model_energy, rounds.last.model_energy);
  // Both end at fixed points of E′. This set's E′ has several minima near
  // the start (E′ = 64.998, 65.057, 65.097): which one the Newton steps
  // reach depends on where their damping starts (μ₀ from 0.3× to 100× of
  // the default gives each of them), the rounds end at the highest. So the
  // Newton steps are asked to converge, to need fewer rounds, and to end
  // no higher, not to meet the rounds' point.
  CHECK(rounds.last.fixed_point_residual < 1e-10);
  CHECK(newton.last.fixed_point_residual < 1e-10);
  CHECK(newton.last.model_energy <= rounds.last.model_energy * (1.0 + 1e-9));
  CHECK(newton.rounds < rounds.rounds);
}

TEST_CASE("bad acceleration settings give clear errors", "[reference][anderson]") {
  const Case c = bend_case(false, 0.5);
  Deformer deformer;
  DeformerOptions options;
  options.anderson_window = 17;
  CHECK_THROWS_WITH(deformer.precompute(c.model, options), Catch::Contains("anderson_window must be in [0, 16]"));
  options.anderson_window = -1;
  CHECK_THROWS_WITH(deformer.precompute(c.model, options), Catch::Contains("anderson_window"));
  options.anderson_window = 3;
  options.rotation_fit = ClusterRotationFit::PaperPhase2;
  CHECK_THROWS_WITH(deformer.precompute(c.model, options), Catch::Contains("needs rotation_fit Exact"));
  options = DeformerOptions{};
  options.tolerance = -1e-3;
  CHECK_THROWS_WITH(deformer.precompute(c.model, options), Catch::Contains("tolerance must be finite and ≥ 0"));
  options.tolerance = std::numeric_limits<double>::quiet_NaN();
  CHECK_THROWS_WITH(deformer.precompute(c.model, options), Catch::Contains("tolerance"));
  options = DeformerOptions{};
  options.cold_start_rounds = -1;
  CHECK_THROWS_WITH(deformer.precompute(c.model, options), Catch::Contains("cold_start_rounds must be in [0, 100000]"));
  options = DeformerOptions{};
  options.cold_start_tolerance = std::numeric_limits<double>::quiet_NaN();
  CHECK_THROWS_WITH(deformer.precompute(c.model, options), Catch::Contains("cold_start_tolerance must be finite"));
  AlternationSettings ao;
  ao.anderson_window = 0;
  CHECK(ao.is_valid(nullptr));
  ao.anderson_window = 17;
  std::string why;
  CHECK_FALSE(ao.is_valid(&why));
  CHECK(why.find("anderson_window") != std::string::npos);
}
