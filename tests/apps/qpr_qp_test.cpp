// `qpr qp` end to end: Matrix Market files written here, the binary run on
// them, its report and solutions checked; malformed inputs rejected with the
// file and line, exit code 2, never a crash.
#include <qpreduce/problems/families.h>
#include <qpreduce/full_solve.h>
#include <qpreduce/problems/matrix_market.h>

#include <catch2/catch.hpp>
#include <nlohmann/json.hpp>

#include <sys/wait.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#ifndef QPR_BINARY
#error "QPR_BINARY must name the qpr executable"
#endif

using namespace qpreduce;
namespace fs = std::filesystem;

namespace {

struct Run {
  int code = -1;
  std::string err;
};

std::string slurp(const fs::path& p) {
  std::ifstream in(p);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

Run run_qpr(const fs::path& dir, const std::string& args) {
  const fs::path err = dir / "stderr.txt";
  const std::string cmd = std::string(QPR_BINARY) + " qp " + args + " > " + (dir / "stdout.txt").string() + " 2> " +
                          err.string();
  const int status = std::system(cmd.c_str());
  Run r;
  r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  r.err = slurp(err);
  return r;
}

fs::path fresh_dir(const std::string& name) {
  const fs::path dir = fs::temp_directory_path() / ("qpreduce_qpr_qp_" + name);
  fs::remove_all(dir);
  fs::create_directories(dir / "demands");
  return dir;
}

struct Written {
  fs::path dir;
  families::QpFamily fam;
  std::vector<families::QpDemand> demands;
};

// A small family as files: H, C, D, and demands in a directory (A_, b_, Y_ or q_).
Written write_family(const std::string& name, families::Family f, bool with_q) {
  Written w{fresh_dir(name), families::make_family(f, 400, 4), {}};
  write_market((w.dir / "H.mtx").string(), w.fam.H, /*symmetric=*/true);
  write_market((w.dir / "C.mtx").string(), w.fam.C);
  write_market((w.dir / "D.mtx").string(), w.fam.D);
  for (int i = 0; i < 3; ++i) {
    w.demands.push_back(families::make_demand(w.fam, static_cast<std::uint64_t>(i)));
    const families::QpDemand& d = w.demands.back();
    const fs::path base = w.dir / "demands";
    const std::string tag = "d" + std::to_string(i);
    write_market((base / ("A_" + tag + ".mtx")).string(), d.A);
    write_market((base / ("b_" + tag + ".mtx")).string(), Matrix<double>(d.b));
    if (with_q) write_market((base / ("q_" + tag + ".mtx")).string(), Matrix<double>(d.q));
    else write_market((base / ("Y_" + tag + ".mtx")).string(), Matrix<double>(d.Y));
  }
  return w;
}

std::string files(const Written& w, const std::string& demands) {
  return "--H " + (w.dir / "H.mtx").string() + " --C " + (w.dir / "C.mtx").string() + " --D " +
         (w.dir / "D.mtx").string() + " --demands " + demands;
}

}  // namespace

TEST_CASE("qpr qp: round trip on Matrix Market files", "[qp][cli]") {
  const families::Family f = GENERATE(families::Family::Gmrf, families::Family::Trajectory,
                                      families::Family::Portfolio);
  const bool with_q = GENERATE(false, true);
  INFO(families::to_string(f) << (with_q ? " with q files" : " with Y files"));
  const Written w = write_family(std::string(families::to_string(f)) + (with_q ? "_q" : "_y"), f, with_q);
  const fs::path report = w.dir / "report.json", out = w.dir / "out";
  // The portfolio's H is PD: exercise --no-augment (factor H itself) there.
  const std::string augment = f == families::Family::Portfolio ? " --no-augment" : "";
  const Run r = run_qpr(w.dir, files(w, (w.dir / "demands").string()) + augment + " --check-full --baseline --report " +
                                   report.string() + " --out " + out.string());
  INFO(r.err);
  REQUIRE(r.code == 0);
  const nlohmann::json doc = nlohmann::json::parse(slurp(report));
  CHECK(doc["n"] == w.fam.n());
  CHECK(doc["failures"] == 0);
  CHECK(doc["violations"] == 0);
  REQUIRE(doc["demands"].size() == 3);
  for (size_t i = 0; i < 3; ++i) {
    const nlohmann::json& d = doc["demands"][i];
    const families::QpDemand& dem = w.demands[i];
    CHECK(d["name"] == "d" + std::to_string(i));
    CHECK(d["status"] == "success");
    CHECK(d["dH_rel_error"].get<double>() <= 1e-10);
    CHECK(d["reduced_seconds"].get<double>() > 0.0);
    CHECK(d["full_seconds"].get<double>() > 0.0);
    CHECK(d["baseline_status"] == "success");
    // n = 400: the dense Theorem 4.10 analysis ran, and in-design demands have error ≈ 0 ≤ bound.
    REQUIRE(d["theorem"]["status"] != "skipped");
    CHECK(d["theorem"]["violation"] == false);
    for (const char* key : {"q_residual", "A_residual", "rho", "norm_q_hat", "norm_b_hat"}) CHECK(d["theorem"].contains(key));
    // The written solution is the full solution.
    MarketReadOptions o;
    o.rows = w.fam.n();
    o.cols = 1;
    const Vector<double> X = read_market_dense((out / ("X_d" + std::to_string(i) + ".mtx")).string(), o).col(0);
    Vector<double> X_full;
    REQUIRE(solve_full(w.fam.H, dem.A, dem.b, dem.q, &X_full).ok());
    CHECK((X - X_full).norm() <= 1e-10 * X_full.norm());
  }
}

TEST_CASE("qpr qp: a JSON manifest and soft constraints", "[qp][cli]") {
  const Written w = write_family("manifest", families::Family::Gmrf, true);
  const fs::path manifest = w.dir / "demands.json";
  std::ofstream(manifest) << R"({"demands": [{"name": "first", "A": "demands/A_d0.mtx", "b": "demands/b_d0.mtx",
                                  "q": "demands/q_d0.mtx"},
                                 {"name": "second", "A": "demands/A_d1.mtx", "b": "demands/b_d1.mtx"}]})";
  const fs::path report = w.dir / "report.json";
  Run r = run_qpr(w.dir, files(w, manifest.string()) + " --report " + report.string());
  INFO(r.err);
  REQUIRE(r.code == 0);
  nlohmann::json doc = nlohmann::json::parse(slurp(report));
  REQUIRE(doc["demands"].size() == 2);
  CHECK(doc["demands"][0]["name"] == "first");
  CHECK(doc["demands"][1]["name"] == "second");
  CHECK(doc["demands"][0]["constraint_residual"].get<double>() <= 1e-10);

  r = run_qpr(w.dir, files(w, manifest.string()) + " --soft 1e6 --check-full --report " + report.string());
  REQUIRE(r.code == 0);
  doc = nlohmann::json::parse(slurp(report));
  CHECK(doc["soft"] == true);
  CHECK(doc["demands"][0]["theorem"]["status"] == "skipped");
  // Soft constraints with a large weight approach the hard answer.
  CHECK(doc["demands"][0]["dH_rel_error"].get<double>() < 1e-2);
}

TEST_CASE("qpr qp: constraints in design coordinates (Ac_ files)", "[qp][cli]") {
  const Written w = write_family("design", families::Family::Portfolio, false);
  // Replace every A_ by its design-coordinate form Ac_ (A = C·A_c).
  for (size_t i = 0; i < w.demands.size(); ++i) {
    const std::string tag = "d" + std::to_string(i);
    fs::remove(w.dir / "demands" / ("A_" + tag + ".mtx"));
    write_market((w.dir / "demands" / ("Ac_" + tag + ".mtx")).string(), w.demands[i].A_c);
  }
  const fs::path report = w.dir / "report.json", out = w.dir / "out";
  const Run r = run_qpr(w.dir, files(w, (w.dir / "demands").string()) + " --no-augment --check-full --report " +
                                   report.string() + " --out " + out.string());
  INFO(r.err);
  REQUIRE(r.code == 0);
  const nlohmann::json doc = nlohmann::json::parse(slurp(report));
  REQUIRE(doc["demands"].size() == 3);
  for (size_t i = 0; i < 3; ++i) {
    const nlohmann::json& d = doc["demands"][i];
    CHECK(d["design_coordinates"] == true);
    CHECK(d["factored"] == true);  // a selection A_c: M_q kept factored
    CHECK(d["dH_rel_error"].get<double>() <= 1e-10);
    CHECK(d["constraint_residual"].get<double>() <= 1e-10);
  }
  // Both A_ and Ac_ for one demand is ambiguous.
  write_market((w.dir / "demands" / "A_d0.mtx").string(), w.demands[0].A);
  const Run both = run_qpr(w.dir, files(w, (w.dir / "demands").string()));
  CHECK(both.code == 2);
  CHECK_THAT(both.err, Catch::Contains("exactly one of A_d0.mtx and Ac_d0.mtx"));
}

TEST_CASE("qpr qp: malformed inputs are rejected with the file and line", "[qp][cli]") {
  const Written w = write_family("malformed", families::Family::Gmrf, false);
  const fs::path demands = w.dir / "demands";
  auto expect_error = [&](const std::string& args, const std::string& fragment) {
    const Run r = run_qpr(w.dir, args);
    INFO(args << "\nstderr: " << r.err);
    CHECK(r.code == 2);
    CHECK_THAT(r.err, Catch::Contains(fragment));
  };

  SECTION("non-symmetric H names the entry's line") {
    const fs::path H = w.dir / "H_bad.mtx";
    std::ofstream(H) << "%%MatrixMarket matrix coordinate real general\n% two rows\n2 2 3\n1 1 2\n2 1 -1\n1 2 -3\n";
    expect_error("--H " + H.string() + " --C " + (w.dir / "C.mtx").string() + " --demands " + demands.string(),
                 H.string() + ":5: not symmetric");
  }
  SECTION("a malformed line in C") {
    const fs::path C = w.dir / "C_bad.mtx";
    std::ofstream(C) << "%%MatrixMarket matrix coordinate real general\n400 1 1\n1 1 one\n";
    expect_error("--H " + (w.dir / "H.mtx").string() + " --C " + C.string() + " --demands " + demands.string(),
                 C.string() + ":3: value 'one' is not a number");
  }
  SECTION("C with the wrong number of rows names the size line") {
    const fs::path C = w.dir / "C_rows.mtx";
    std::ofstream(C) << "%%MatrixMarket matrix coordinate real general\n%\n399 1 1\n1 1 1\n";
    expect_error("--H " + (w.dir / "H.mtx").string() + " --C " + C.string() + " --demands " + demands.string(),
                 C.string() + ":3: expected 400 rows, got 399");
  }
  SECTION("b with the wrong size") {
    const fs::path b = demands / "b_d1.mtx";
    std::ofstream(b) << "%%MatrixMarket matrix array real general\n2 1\n1\n2\n";
    expect_error(files(w, demands.string()), b.string() + ":2: expected");
  }
  SECTION("NaN in a demand's A") {
    const fs::path A = demands / "A_d2.mtx";
    std::ofstream(A) << "%%MatrixMarket matrix coordinate real general\n400 1 1\n3 1 NaN\n";
    expect_error(files(w, demands.string()), A.string() + ":3: value 'NaN' is not finite");
  }
  SECTION("a demand without b, a broken manifest, a missing path") {
    fs::remove(demands / "b_d0.mtx");
    expect_error(files(w, demands.string()), "has no b_d0.mtx");
    write_market((demands / "b_d0.mtx").string(), Matrix<double>(w.demands[0].b));
    fs::remove(demands / "A_d1.mtx");
    expect_error(files(w, demands.string()), "needs exactly one of A_d1.mtx and Ac_d1.mtx");
    const fs::path manifest = w.dir / "bad.json";
    std::ofstream(manifest) << "{\"demands\": [\n  {\"A\": \"x\",}\n]}\n";
    expect_error(files(w, manifest.string()), "line 2");
    expect_error(files(w, (w.dir / "nowhere").string()), "no such file");
  }
}
