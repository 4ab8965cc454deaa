// Deformer::save / Deformer::load: the precomputed model on disk (binary,
// versioned, CRC-32 checked). A loaded session must give the same frames as
// the one that was saved; a corrupted, truncated or mismatched file must be
// refused with a message and leave the session as it was.
#include <catch2/catch.hpp>

#include "qpreduce/deform/deformer/deformer.h"
#include "qpreduce/deform/io/io_error.h"
#include "qpreduce/deform/mesh/shapes.h"

#include <Eigen/Geometry>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>

using namespace qpreduce;
using namespace qpreduce::deform;

namespace {

namespace fs = std::filesystem;

// A patch-handled cylinder (fixed bottom, affine top) bent by its top patch.
struct Case {
  DeformableMesh model;
  SelDefScenario scenario;
};

Case bent_cylinder() {
  Case c;
  const TriangleMesh m = shapes::capped_cylinder(0.5, 3.0, 12, 16);
  c.model.V = m.V;
  c.model.F = m.F;
  std::vector<int> sel(static_cast<size_t>(m.V.rows()), 1);
  for (Index v = 0; v < m.V.rows(); ++v) {
    if (m.V(v, 2) < 0.4) sel[v] = 0;
    if (m.V(v, 2) > 2.6) sel[v] = 2;
  }
  Eigen::Matrix4d def = Eigen::Matrix4d::Identity();
  def.topLeftCorner<3, 3>() = Eigen::AngleAxisd(0.9, Eigen::Vector3d::UnitX()).toRotationMatrix();
  def.block<3, 1>(0, 3) = Eigen::Vector3d(0.0, 1.2, -0.4);
  c.scenario = apply_sel_def(sel, def, &c.model);
  return c;
}

DeformerOptions small_options() {
  DeformerOptions o;
  o.rotational_proxies = 6;
  o.linear_proxies = 5;
  return o;
}

// Three frames; returns the last one.
Vertices run(Deformer& deformer, const Case& c) {
  REQUIRE(deformer.set_handles(c.scenario.handles).ok());
  Vertices out;
  for (int f = 0; f < 3; ++f) deformer.frame(c.scenario.targets, &out);
  return out;
}

std::string temp_path(const std::string& name) {
  return (fs::temp_directory_path() / ("qpreduce_cache_test_" + name)).string();
}

std::string read_all(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

void write_all(const std::string& path, const std::string& bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
}

// Expects load to throw an IoError whose message contains `needle`.
void require_refused(const std::string& path, const Case& c, const DeformerOptions& o, const std::string& needle) {
  Deformer other;
  try {
    other.load(path, c.model, o);
    FAIL("load accepted " << path);
  } catch (const IoError& e) {
    INFO(e.what());
    CHECK(std::string(e.what()).find(needle) != std::string::npos);
    CHECK(e.file() == path);
  }
  CHECK_FALSE(other.ready());
}

}  // namespace

TEST_CASE("cache: a loaded model gives the frames of the saved one", "[cache]") {
  const Case c = bent_cylinder();
  const DeformerOptions o = small_options();
  Deformer original;
  REQUIRE(original.precompute(c.model, o).ok());
  const std::string path = temp_path("roundtrip.qpr");
  original.save(path);
  CHECK_FALSE(fs::exists(path + ".tmp"));
  const Vertices expected = run(original, c);

  Deformer loaded;
  const PrecomputeSummary ps = loaded.load(path, c.model, o);
  INFO(ps.message);
  REQUIRE(ps.ok());
  CHECK(ps.vertices == c.model.V.rows());
  CHECK(ps.rotational_proxies == original.rotational_proxies());
  CHECK(ps.linear_proxies == original.linear_proxies());
  CHECK(ps.patches == 2);
  CHECK(loaded.clusters() == original.clusters());
  const Vertices got = run(loaded, c);
  const double moved = (expected - c.model.V).cwiseAbs().maxCoeff();
  CHECK(moved > 0.1);  // the scenario does deform the mesh
  CHECK((got - expected).cwiseAbs().maxCoeff() <= 1e-12 * moved);

  // Runtime options come from the caller, not the file.
  DeformerOptions more = o;
  more.iterations = 1;
  Deformer one_round;
  REQUIRE(one_round.load(path, c.model, more).ok());
  CHECK((run(one_round, c) - expected).cwiseAbs().maxCoeff() > 1e-9 * moved);
  fs::remove(path);
}

TEST_CASE("cache: a file made from other inputs is refused, naming the difference", "[cache][errors]") {
  const Case c = bent_cylinder();
  const DeformerOptions o = small_options();
  Deformer d;
  REQUIRE(d.precompute(c.model, o).ok());
  const std::string path = temp_path("mismatch.qpr");
  d.save(path);

  DeformerOptions stiffer = o;
  stiffer.energy.alpha = 1.0;
  require_refused(path, c, stiffer, "energy.alpha");
  DeformerOptions more_proxies = o;
  more_proxies.rotational_proxies = 7;
  require_refused(path, c, more_proxies, "rotational_proxies");

  Case moved = c;
  moved.model.V(5, 1) += 1e-9;
  require_refused(path, moved, o, "rest positions differ (first at row 5)");

  Case other_patches = c;
  for (int& p : other_patches.model.patch_of_vertex)
    if (p == 1) p = -1;
  other_patches.model.patch_types.pop_back();
  require_refused(path, other_patches, o, "patch");

  const TriangleMesh bigger = shapes::capped_cylinder(0.5, 3.0, 12, 17);
  Case other_mesh = c;
  other_mesh.model.V = bigger.V;
  other_mesh.model.F = bigger.F;
  other_mesh.model.patch_of_vertex.clear();
  other_mesh.model.patch_types.clear();
  require_refused(path, other_mesh, o, "vertices");
  fs::remove(path);
}

TEST_CASE("cache: corrupted, truncated and foreign files are refused", "[cache][errors]") {
  const Case c = bent_cylinder();
  const DeformerOptions o = small_options();
  Deformer d;
  REQUIRE(d.precompute(c.model, o).ok());
  const std::string good = temp_path("good.qpr");
  d.save(good);
  const std::string bytes = read_all(good);
  REQUIRE(bytes.size() > 1000);
  const std::string bad = temp_path("bad.qpr");

  SECTION("one flipped bit in the payload") {
    std::string b = bytes;
    b[b.size() / 2] = static_cast<char>(b[b.size() / 2] ^ 0x10);
    write_all(bad, b);
    require_refused(bad, c, o, "corrupted: CRC-32");
  }
  SECTION("truncated") {
    write_all(bad, bytes.substr(0, bytes.size() - 100));
    require_refused(bad, c, o, "truncated");
  }
  SECTION("shorter than a header") {
    write_all(bad, bytes.substr(0, 10));
    require_refused(bad, c, o, "truncated");
  }
  SECTION("not a cache") {
    write_all(bad, std::string(200, 'x'));
    require_refused(bad, c, o, "not a qpreduce deformer cache");
  }
  SECTION("another format version") {
    std::string b = bytes;
    b[16] = static_cast<char>(b[16] + 1);
    write_all(bad, b);
    require_refused(bad, c, o, "format version");
  }
  SECTION("missing") { require_refused(temp_path("does_not_exist.qpr"), c, o, "cannot open"); }
  fs::remove(bad);
  fs::remove(good);
}

TEST_CASE("cache: a refused load leaves the session as it was", "[cache][errors]") {
  const Case c = bent_cylinder();
  const DeformerOptions o = small_options();
  Deformer d;
  REQUIRE(d.precompute(c.model, o).ok());
  const Vertices before = run(d, c);
  d.reset_pose();
  const std::string bad = temp_path("garbage.qpr");
  write_all(bad, std::string(500, '\0'));
  CHECK_THROWS_AS(d.load(bad, c.model, o), IoError);
  REQUIRE(d.ready());
  const Vertices after = run(d, c);
  CHECK((after - before).cwiseAbs().maxCoeff() == 0.0);
  fs::remove(bad);

  Deformer empty;
  CHECK_THROWS_AS(empty.save(temp_path("never.qpr")), std::invalid_argument);
}
