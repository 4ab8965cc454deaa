// run_scenario (pipeline/run_scenario.h): the frames it runs are the ones a
// caller running the Deformer by hand gets; settle reaches its tolerance and
// restores the round settings; refine lowers the classic energy from the
// settled pose; the hooks see every stage; a cache round-trips and a broken
// one is named and passed over; bad settings throw clear errors.
#include <catch2/catch.hpp>

#include "../io/io_test_util.h"
#include "../reference/reference_test_util.h"

#include "qpreduce/deform/energy/arap_energy.h"
#include "qpreduce/deform/pipeline/run_scenario.h"

#include <string>
#include <vector>

using namespace qpreduce;
using namespace qpreduce::deform;
using io_test::TempDir;

namespace {

// The bent capped cylinder of the reference tests, reached in three frames.
Scenario bend_scenario() {
  const reference_test::Case c = reference_test::bend_case(false, 0.6);
  Scenario sc;
  sc.model = c.model;
  sc.handles = c.handles;
  sc.constraints = c.constraints;
  sc.frames.assign(3, c.targets);
  return sc;
}

ScenarioRunOptions run_options() {
  ScenarioRunOptions o;
  o.deformer.linear_proxies = 6;
  o.deformer.rotational_proxies = 4;
  o.deformer.iterations = 6;
  o.deformer.tolerance = 0.0;
  o.deformer.time_budget = 0.0;  // rounds by count: the same poses every run
  return o;
}

// The last frame's pose of a Deformer driven by hand through the scenario.
Vertices by_hand_pose(const Scenario& sc, const DeformerOptions& options) {
  Deformer by_hand;
  REQUIRE(by_hand.precompute(sc.model, options).ok());
  REQUIRE(usable(by_hand.set_handles(sc.handles, sc.constraints).status));
  Vertices V;
  for (const HandleTargets& t : sc.frames) REQUIRE(usable(by_hand.frame(t, &V).status));
  return V;
}

}  // namespace

TEST_CASE("run_scenario runs the frames a caller running the Deformer by hand gets") {
  const Scenario sc = bend_scenario();
  const ScenarioRunOptions o = run_options();
  Deformer deformer;
  ScenarioPoses poses;
  std::vector<int> seen;
  int prepared = 0;
  ScenarioRunHooks hooks;
  hooks.prepared = [&](const Deformer& d, bool from_cache) {
    ++prepared;
    CHECK_FALSE(from_cache);
    CHECK(d.elements().size() > 0);
  };
  hooks.frame = [&](int f, const Vertices& pose) {
    seen.push_back(f);
    CHECK(pose.rows() == sc.model.V.rows());
  };
  const ScenarioRunSummary s = run_scenario(sc, o, &deformer, &poses, hooks);
  REQUIRE(s.ok());
  CHECK(s.stage == ScenarioStage::Done);
  CHECK(prepared == 1);
  CHECK(seen == std::vector<int>{0, 1, 2});
  REQUIRE(s.frames.size() == 3);
  REQUIRE(s.handle_residual.size() == 3);
  CHECK_FALSE(s.settled);
  CHECK_FALSE(s.refined);
  CHECK(poses.settled.size() == 0);
  CHECK(poses.refined.size() == 0);
  CHECK(s.frames[0].cold_start);  // the first frame after set_handles (DeformerOptions::cold_start_rounds)
  for (size_t f = 1; f < s.frames.size(); ++f) CHECK(s.frames[f].iterations == 6);

  CHECK(reference_test::max_distance(by_hand_pose(sc, o.deformer), poses.last) <= 1e-12 * s.diagonal);
  CHECK(s.arap_energy == Approx(arap_energy(sc.model.V, deformer.elements(), poses.last)).epsilon(1e-12));
  CHECK(s.handles.status == Status::Success);
  CHECK(s.op_seconds > 0.0);
  CHECK(s.options.iterations == o.deformer.iterations);  // no override in this scenario
}

TEST_CASE("run_scenario reports the options it ran with: the scenario's overrides on top of the caller's") {
  Scenario sc = bend_scenario();
  sc.iterations = 3;
  sc.gamma = 0.25;
  const ScenarioRunOptions o = run_options();
  Deformer deformer;
  ScenarioPoses poses;
  const ScenarioRunSummary s = run_scenario(sc, o, &deformer, &poses);
  REQUIRE(s.ok());
  CHECK(s.options.iterations == 3);
  CHECK(s.options.energy.gamma == 0.25);
  CHECK(s.options.energy.alpha == o.deformer.energy.alpha);
  // A deformer driven by hand with those options gets the same frames.
  CHECK(reference_test::max_distance(by_hand_pose(sc, s.options), poses.last) <= 1e-12 * s.diagonal);
}

TEST_CASE("run_scenario settles the last frame, refines from there and restores the round settings") {
  const Scenario sc = bend_scenario();
  ScenarioRunOptions o = run_options();
  o.refine = RefineOptions{};
  o.refine->threads = 1;
  Deformer deformer;
  ScenarioPoses poses;
  const ScenarioRunSummary s = run_scenario(sc, o, &deformer, &poses);
  REQUIRE(s.ok());
  REQUIRE(s.settled);
  REQUIRE(s.refined);
  CHECK(s.settle.iterations > 0);  // six rounds a frame leave the last short of 1e-6
  CHECK(s.settle.fixed_point_residual <= o.settle_tolerance);
  CHECK(s.frames.back().fixed_point_residual > o.settle_tolerance);
  const double settled = arap_energy(sc.model.V, deformer.elements(), poses.settled);
  const double last = arap_energy(sc.model.V, deformer.elements(), poses.last);
  CHECK(s.refine.arap_energy <= settled);
  CHECK(s.refine.arap_energy < last);
  CHECK(s.arap_energy == Approx(s.refine.arap_energy).epsilon(1e-12));
  CHECK(s.refine.initial_energy == Approx(settled).epsilon(1e-9));
  // The deformer runs its own round settings again: six rounds a frame.
  Vertices V;
  CHECK(deformer.frame(sc.frames.back(), &V).iterations == 6);

  // Settle alone, with a last frame already at the tolerance: no rounds, the frame's pose.
  ScenarioRunOptions loose = run_options();
  loose.settle = true;
  loose.settle_tolerance = 1.0;
  Deformer d2;
  ScenarioPoses p2;
  const ScenarioRunSummary s2 = run_scenario(sc, loose, &d2, &p2);
  REQUIRE(s2.ok());
  CHECK(s2.settled);
  CHECK(s2.settle.iterations == 0);
  CHECK(p2.settled == p2.last);
}

TEST_CASE("run_scenario loads a cache it is given, and names a broken one before precomputing") {
  const Scenario sc = bend_scenario();
  TempDir dir;
  ScenarioRunOptions o = run_options();
  o.cache_path = dir.path("model.qpr");
  Deformer first;
  ScenarioPoses p1;
  ScenarioRunHooks hooks;
  hooks.prepared = [&](const Deformer& d, bool from_cache) {
    if (!from_cache) d.save(o.cache_path);
  };
  const ScenarioRunSummary s1 = run_scenario(sc, o, &first, &p1, hooks);
  REQUIRE(s1.ok());
  CHECK_FALSE(s1.from_cache);
  CHECK(s1.cache_message.empty());

  Deformer second;
  ScenarioPoses p2;
  const ScenarioRunSummary s2 = run_scenario(sc, o, &second, &p2);
  REQUIRE(s2.ok());
  CHECK(s2.from_cache);
  CHECK(reference_test::max_distance(p1.last, p2.last) <= 1e-12 * s1.diagonal);

  o.cache_path = dir.write("broken.qpr", "not a cache");
  Deformer third;
  const ScenarioRunSummary s3 = run_scenario(sc, o, &third);
  REQUIRE(s3.ok());
  CHECK_FALSE(s3.from_cache);
  CHECK_THAT(s3.cache_message, Catch::Contains("broken.qpr"));
}

TEST_CASE("run_scenario refuses bad settings with a message naming them") {
  const Scenario sc = bend_scenario();
  Deformer deformer;
  ScenarioRunOptions o = run_options();
  CHECK_THROWS_WITH(run_scenario(sc, o, nullptr), Catch::Contains("deformer is null"));
  o.settle_rounds = 0;
  CHECK_THROWS_WITH(run_scenario(sc, o, &deformer), Catch::Contains("settle_rounds must be ≥ 1, got 0"));
  o = run_options();
  o.settle_tolerance = -1.0;
  CHECK_THROWS_WITH(run_scenario(sc, o, &deformer), Catch::Contains("settle_tolerance must be finite"));
  o = run_options();
  o.refine = RefineOptions{};
  o.refine->anderson_window = 99;
  CHECK_THROWS_WITH(run_scenario(sc, o, &deformer), Catch::Contains("refine: "));
  Scenario empty = sc;
  empty.frames.clear();
  CHECK_THROWS_WITH(run_scenario(empty, run_options(), &deformer), Catch::Contains("no frames"));
}
