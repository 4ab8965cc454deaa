// Deformer::save / Deformer::load: the precomputed model on disk (binary,
// versioned, CRC-32 checked). A loaded session must give the same frames as
// the one that was saved; a corrupted, truncated or mismatched file must be
// refused with a message and leave the session as it was.
#include <catch2/catch.hpp>

#include "qpreduce/deform/deformer/cache_file.h"
#include "qpreduce/deform/deformer/deformer.h"
#include "qpreduce/deform/io/io_error.h"
#include "qpreduce/deform/mesh/shapes.h"

#include <Eigen/Geometry>

#include <condition_variable>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <utility>
#include <vector>

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
  // A fixed count of rounds every frame (8, no cold start to a tolerance, no
  // time budget): the frames of two models then differ by what the models
  // differ by, not by the round at which a tolerance test or the clock
  // happened to stop them.
  o.iterations = 8;
  o.tolerance = 0.0;
  o.time_budget = 0.0;
  o.cold_start_rounds = 0;
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
  // The file holds the float basis and the reduced operators as they were:
  // the frames are the same, bit for bit.
  CHECK(loaded.reconstruction_basis() == original.reconstruction_basis());
  CHECK(got == expected);

  // Runtime options come from the caller, not the file.
  DeformerOptions more = o;
  more.iterations = 1;
  Deformer one_round;
  REQUIRE(one_round.load(path, c.model, more).ok());
  CHECK((run(one_round, c) - expected).cwiseAbs().maxCoeff() > 1e-9 * moved);
  fs::remove(path);
}

TEST_CASE("cache: a double-basis model comes back in double, and only for double_basis", "[cache]") {
  const Case c = bent_cylinder();
  DeformerOptions o = small_options();
  o.double_basis = true;
  Deformer original;
  REQUIRE(original.precompute(c.model, o).ok());
  REQUIRE(original.double_basis());
  CHECK(original.reconstruction_basis().size() == 0);
  const Index p = original.reconstruction_basis_double().cols();
  CHECK(original.reconstruction_basis_double().rows() == 3 * c.model.V.rows());
  const std::string path = temp_path("double.qpr");
  original.save(path);
  const Vertices expected = run(original, c);
  CHECK(original.reduced_coordinates_double().size() == p);

  Deformer loaded;
  REQUIRE(loaded.load(path, c.model, o).ok());
  CHECK(loaded.reconstruction_basis_double() == original.reconstruction_basis_double());
  CHECK(run(loaded, c) == expected);

  // The float basis's session reaches the same pose up to float round-off.
  Deformer in_float;
  REQUIRE(in_float.precompute(c.model, small_options()).ok());
  const Vertices f = run(in_float, c);
  const double moved = (expected - c.model.V).cwiseAbs().maxCoeff();
  CHECK((f - expected).cwiseAbs().maxCoeff() <= 1e-5 * moved);
  CHECK((f - expected).cwiseAbs().maxCoeff() > 0.0);

  require_refused(path, c, small_options(), "option double_basis is 1 in the cache, 0 given");
  // Float blocks cannot stand for a double basis.
  CHECK_THROWS_WITH(original.save(temp_path("double_blocks.qpr"),
                                  [](Index*, Deformer::BasisRows*) { return false; }),
                    Catch::Contains("keeps its basis in double"));
  CHECK_FALSE(fs::exists(temp_path("double_blocks.qpr")));
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

TEST_CASE("cache: save replaces a cache or an empty file, never another file", "[cache][errors]") {
  const Case c = bent_cylinder();
  Deformer d;
  REQUIRE(d.precompute(c.model, small_options()).ok());
  const std::string path = temp_path("replace.qpr");
  const std::string mesh = "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n";
  write_all(path, mesh);
  CHECK_FALSE(is_deformer_cache(path));
  CHECK_THROWS_WITH(d.save(path), Catch::Contains("exists and is not a qpreduce deformer cache"));
  CHECK(read_all(path) == mesh);
  write_all(path, "");
  d.save(path);
  CHECK(is_deformer_cache(path));
  d.save(path);  // a cache is replaced
  CHECK(is_deformer_cache(path));
  CHECK_FALSE(is_deformer_cache(temp_path("does_not_exist.qpr")));
  CHECK(may_replace_with_cache(temp_path("does_not_exist.qpr")));
  CHECK(may_replace_with_cache("/dev/null"));
  fs::remove(path);
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

namespace {

// K "processes" as threads of this test: the sum of Deformer::precompute_part
// as a reusable barrier that adds everyone's matrix (an all-reduce).
class ThreadSum {
 public:
  explicit ThreadSum(int parts) : parts_(parts) {}
  void operator()(Matrix<double>* M) {
    std::unique_lock<std::mutex> lock(mutex_);
    const std::uint64_t round = round_;
    if (arrived_ == 0) {
      sum_ = *M;
    } else {
      sum_ += *M;
    }
    if (++arrived_ == parts_) {
      result_ = sum_;
      arrived_ = 0;
      ++round_;
      done_.notify_all();
    } else {
      done_.wait(lock, [&] { return round_ != round; });
    }
    *M = result_;
  }

 private:
  const int parts_;
  std::mutex mutex_;
  std::condition_variable done_;
  int arrived_ = 0;
  std::uint64_t round_ = 0;
  Matrix<double> sum_, result_;
};

// One single-process build shared by every part, made by the one-part
// (K = 1) precompute, whose rows are the whole H_u, C, D_u of the
// single-process assembly; it keeps them, so that each part's rows (the
// distributed assembly) can be compared with them. Each part building
// its own would test CHOLMOD's reproducibility across threads, which does
// not hold bit for bit (docs/scaling.md, "What is bit-identical").
struct SharedBuild {
  SubspaceSolver<double> solver;
  SubspaceSummary summary;
  SparseMatrix<double> H, D;                         // n_u × n_u, n_u × 9d
  std::vector<SparseMatrix<double>> H_rows, D_rows;  // what each of K parts assembled
};

Deformer::PartBuilder whole_build(SharedBuild* shared) {
  return [shared](const SparseMatrix<double>& H, const SparseMatrix<double>& C, const SparseMatrix<double>& D,
                  const SubspaceOptions& options, Deformer::SubspacePart* part) {
    shared->H = H;
    shared->D = D;
    shared->summary = shared->solver.precompute(H, C, D, options);
    if (!shared->summary.ok()) return shared->summary;
    part->first_row = 0;
    part->N_rows = shared->solver.subspace().N;
    part->UD_rows = shared->solver.subspace().UD;
    part->Hr = shared->solver.reduced_hessian();
    part->BtD = shared->solver.reduced_linear_map();
    return shared->summary;
  };
}

// Part t of K: keeps the rows it assembled (H_rows, D_rows sized K), and
// returns rows [⌊t·n/K⌋, ⌊(t+1)·n/K⌋) of the shared build.
Deformer::PartBuilder rows_of_shared_build(SharedBuild* shared, int t, int K) {
  return [shared, t, K](const SparseMatrix<double>& H, const SparseMatrix<double>&, const SparseMatrix<double>& D,
                        const SubspaceOptions&, Deformer::SubspacePart* part) {
    if (static_cast<int>(shared->H_rows.size()) == K) {
      shared->H_rows[static_cast<size_t>(t)] = H;
      shared->D_rows[static_cast<size_t>(t)] = D;
    }
    const SubspaceSolver<double>& solver = shared->solver;
    const Index n = H.cols(), begin = t * n / K, end = (t + 1) * n / K;
    part->first_row = begin;
    part->N_rows = solver.subspace().N.middleRows(begin, end - begin);
    part->UD_rows = solver.subspace().UD.middleRows(begin, end - begin);
    part->Hr = solver.reduced_hessian();
    part->BtD = solver.reduced_linear_map();
    return shared->summary;
  };
}

// K parts of `model` on threads, each with the sum over the threads.
std::vector<PrecomputeSummary> run_parts(const DeformableMesh& model, const DeformerOptions& o, SharedBuild* shared,
                                         std::vector<Deformer>* parts) {
  const int K = static_cast<int>(parts->size());
  std::vector<PrecomputeSummary> summaries(static_cast<size_t>(K));
  ThreadSum sum(K);
  std::vector<std::thread> threads;
  for (int t = 0; t < K; ++t) {
    threads.emplace_back([&, t] {
      summaries[t] = (*parts)[t].precompute_part(model, o, {}, {t, K}, rows_of_shared_build(shared, t, K),
                                                 [&sum](Matrix<double>* M) { sum(M); });
    });
  }
  for (auto& th : threads) th.join();
  return summaries;
}

double relative_difference(const SparseMatrix<double>& a, const SparseMatrix<double>& b) {
  return SparseMatrix<double>(a - b).norm() / std::max(b.norm(), 1e-300);
}

// K parts assemble only their rows of H_u and D_u (on part of the elements;
// `whole_allowed` parts may need every element, as the first does with Q
// kept when it owns every vertex row), and those rows are the whole
// assembly's (the one-part run) to round-off; the float basis rows match the
// single-process precompute's.
void check_assembled_rows(const DeformableMesh& model, const DeformerOptions& o, int K, int whole_allowed = 0) {
  SharedBuild shared;
  Deformer one;
  REQUIRE(one.precompute_part(model, o, {}, {0, 1}, whole_build(&shared), [](Matrix<double>*) {}).ok());
  Deformer reference;
  REQUIRE(reference.precompute(model, o).ok());
  shared.H_rows.resize(static_cast<size_t>(K));
  shared.D_rows.resize(static_cast<size_t>(K));
  std::vector<Deformer> parts(static_cast<size_t>(K));
  const std::vector<PrecomputeSummary> summaries = run_parts(model, o, &shared, &parts);
  const Index n = shared.H.rows();
  Index assembled = 0;
  int whole = 0;
  for (int t = 0; t < K; ++t) {
    INFO("part " << t << " of " << K << ": " << summaries[t].message);
    REQUIRE(summaries[t].ok());
    const Index begin = t * n / K, end = (t + 1) * n / K;
    REQUIRE(shared.H_rows[t].rows() == end - begin);
    REQUIRE(shared.H_rows[t].cols() == n);
    // The same sums in another order: round-off only.
    CHECK(relative_difference(shared.H_rows[t], shared.H.middleRows(begin, end - begin)) < 1e-13);
    CHECK(relative_difference(shared.D_rows[t], shared.D.middleRows(begin, end - begin)) < 1e-13);
    CHECK(summaries[t].assembled_elements <= summaries[t].elements);
    if (summaries[t].assembled_elements == summaries[t].elements) ++whole;
    assembled += summaries[t].assembled_elements;
    const auto rows = parts[t].basis_rows();
    if (rows.count == 0) continue;
    CHECK(parts[t].reconstruction_basis().size() == 0);  // K > 1: the double rows, float rows on demand
    Deformer::BasisRows a;
    parts[t].basis_block(rows.first, rows.count, &a);
    const Matrix<float> b = reference.reconstruction_basis().middleRows(rows.first, rows.count);
    CHECK((Matrix<float>(a) - b).norm() <= 1e-5 * b.norm());
  }
  CHECK(whole <= whole_allowed);
  CHECK(assembled >= summaries[0].elements);  // each element by its owner, and as a ghost where needed
}

}  // namespace

TEST_CASE("cache: a precompute in parts assembles only its rows, and they match the whole assembly",
          "[cache][parts]") {
  SECTION("surface with two patches, whose rows are summed over the parts") {
    check_assembled_rows(bent_cylinder().model, small_options(), 3);
  }
  SECTION("surface, the paper's Phase 2") {
    DeformerOptions o = small_options();
    o.rotation_fit = ClusterRotationFit::PaperPhase2;
    o.anderson_window = 0;  // its safeguard needs the exact fit
    check_assembled_rows(bent_cylinder().model, o, 2);
  }
  SECTION("tetrahedra, conformal, two patches") {
    const TetMesh bar = shapes::box_tets(3.0, 1.0, 1.0, 6, 2, 2);
    DeformableMesh model;
    model.V = bar.V;
    model.T = bar.T;
    std::vector<int> sel(static_cast<size_t>(bar.V.rows()), 1);
    for (Index v = 0; v < bar.V.rows(); ++v) {
      if (bar.V(v, 0) < 0.1) sel[v] = 0;
      if (bar.V(v, 0) > 2.9) sel[v] = 2;
    }
    apply_sel_def(sel, Eigen::Matrix4d::Identity(), &model);
    DeformerOptions o = small_options();
    o.model = ModelKind::Conformal;
    check_assembled_rows(model, o, 3);
    SECTION("and gamma > 0: Q kept, its rows need each element's neighbours") {
      o.energy.gamma = 0.5;
      // 4 rows of Q per tet outnumber the vertex rows: the first part owns them all.
      check_assembled_rows(model, o, 3, 1);
    }
  }
  SECTION("surface with two patches, gamma > 0 (Q kept in u)") {
    DeformerOptions o = small_options();
    o.energy.gamma = 0.5;
    check_assembled_rows(bent_cylinder().model, o, 3);
    SECTION("and the paper's Phase 2") {
      o.rotation_fit = ClusterRotationFit::PaperPhase2;
      o.anderson_window = 0;
      check_assembled_rows(bent_cylinder().model, o, 4);
    }
  }
}

TEST_CASE("cache: a precompute in parts, saved block by block, gives the frames of the whole one",
          "[cache][parts]") {
  const Case c = bent_cylinder();  // two patches: their rows of B come from the last part
  const DeformerOptions o = small_options();
  Deformer whole;
  REQUIRE(whole.precompute(c.model, o).ok());
  SharedBuild shared;
  Deformer one_part;  // K = 1: the whole basis, from the build the parts share
  REQUIRE(one_part.precompute_part(c.model, o, {}, {0, 1}, whole_build(&shared), [](Matrix<double>*) {}).ok());
  const auto& full = one_part.reconstruction_basis();
  REQUIRE(full.rows() == whole.reconstruction_basis().rows());
  CHECK(one_part.basis_rows().first == 0);
  // A partition without this process, or a builder returning other rows than it owns, is refused.
  Deformer refused;
  CHECK_THROWS_WITH(refused.precompute_part(c.model, o, {}, {2, 2}, whole_build(&shared), [](Matrix<double>*) {}),
                    Catch::Contains("process 2 of 2"));
  CHECK_THROWS_WITH(refused.precompute_part(c.model, o, {}, {0, 1}, rows_of_shared_build(&shared, 1, 2),
                                            [](Matrix<double>*) {}),
                    Catch::Contains("owns [0,"));

  constexpr int K = 3;
  std::vector<Deformer> parts(K);
  const std::vector<PrecomputeSummary> summaries = run_parts(c.model, o, &shared, &parts);
  Index covered = 0;
  for (int t = 0; t < K; ++t) {
    INFO("part " << t << ": " << summaries[t].message);
    REQUIRE(summaries[t].ok());
    const auto rows = parts[t].basis_rows();
    if (rows.count == 0) continue;
    CHECK(rows.first == covered);
    // The rows of the one-part basis, bit for bit (the same doubles, the
    // same products), whole and in odd pieces.
    Deformer::BasisRows mine, piece;
    parts[t].basis_block(rows.first, rows.count, &mine);
    CHECK(mine == full.middleRows(rows.first, rows.count));
    for (Index i = 0; i < rows.count; i += 5) {
      const Index c = std::min<Index>(5, rows.count - i);
      parts[t].basis_block(rows.first + i, c, &piece);
      CHECK(piece == full.middleRows(rows.first + i, c));
    }
    CHECK_THROWS_WITH(parts[t].basis_block(rows.first + 1, rows.count, &piece), Catch::Contains("outside"));
    covered += rows.count;
  }
  CHECK(covered == full.rows());
  CHECK_THROWS_WITH(parts[0].set_handles(c.scenario.handles), Catch::Contains("part of a distributed precompute"));
  CHECK_THROWS_WITH(parts[0].save(temp_path("part.qpr")), Catch::Contains("save(path, blocks)"));

  // Saved by part 0 with every part's rows in blocks of 7 rows.
  int source = 0;
  Index done = 0;
  const Deformer::BasisBlocks blocks = [&](Index* first, Deformer::BasisRows* rows) {
    for (; source < K; ++source, done = 0) {
      const auto mine = parts[source].basis_rows();
      if (done == mine.count) continue;
      const Index c7 = std::min<Index>(7, mine.count - done);
      parts[source].basis_block(mine.first + done, c7, rows);
      *first = mine.first + done;
      done += c7;
      return true;
    }
    return false;
  };
  const std::string path = temp_path("parts.qpr");
  parts[0].save(path, blocks);
  Deformer loaded;
  REQUIRE(loaded.load(path, c.model, o).ok());
  CHECK(loaded.reconstruction_basis() == full);
  const Vertices expected = run(whole, c);
  const double moved = (expected - c.model.V).cwiseAbs().maxCoeff();
  // Against the ordinary precompute (its own build) and with M_N, M_U summed
  // part by part: the doubles agree to round-off, which can move the float
  // reconstruction of the frame (V′ = B·w in float) by an ulp: 6e-8 of
  // coordinates up to ~3 here.
  CHECK((run(loaded, c) - expected).cwiseAbs().maxCoeff() <= 1e-6 * moved);
  fs::remove(path);
}

TEST_CASE("cache: basis blocks that do not tile the rows are refused, no file left", "[cache][parts][errors]") {
  const Case c = bent_cylinder();
  const DeformerOptions o = small_options();
  Deformer d;
  REQUIRE(d.precompute(c.model, o).ok());
  const auto& B = d.reconstruction_basis();
  const Index half = B.rows() / 2;
  const std::string path = temp_path("blocks.qpr");
  d.save(path);
  const std::string before = read_all(path);
  // Blocks given as (first, rows) pairs.
  auto given = [&](std::vector<std::pair<Index, Deformer::BasisRows>> list) {
    auto at = std::make_shared<size_t>(0);
    return Deformer::BasisBlocks([list, at](Index* first, Deformer::BasisRows* rows) {
      if (*at == list.size()) return false;
      *first = list[*at].first;
      *rows = list[*at].second;
      ++*at;
      return true;
    });
  };
  const Deformer::BasisRows top = B.topRows(half), bottom = B.bottomRows(B.rows() - half);
  Deformer::BasisRows nan = bottom;
  nan(0, 0) = std::numeric_limits<float>::quiet_NaN();
  CHECK_THROWS_WITH(d.save(path, given({{0, top}})), Catch::Contains("end at row"));
  CHECK_THROWS_WITH(d.save(path, given({{0, top}, {half + 1, bottom}})), Catch::Contains("was due"));
  CHECK_THROWS_WITH(d.save(path, given({{0, top}, {0, top}})), Catch::Contains("was due"));
  CHECK_THROWS_WITH(d.save(path, given({{0, top}, {half, bottom.leftCols(3)}})), Catch::Contains("columns"));
  CHECK_THROWS_WITH(d.save(path, given({{0, top}, {half, nan}})), Catch::Contains("NaN"));
  CHECK(read_all(path) == before);  // the earlier cache is untouched
  CHECK_FALSE(fs::exists(path + ".tmp"));
  d.save(path, given({{0, top}, {half, bottom}}));
  Deformer loaded;
  REQUIRE(loaded.load(path, c.model, o).ok());
  CHECK(loaded.reconstruction_basis() == B);
  fs::remove(path);
}
