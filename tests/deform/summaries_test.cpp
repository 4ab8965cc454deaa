// Every summary's report (Outcome::report()): its keys are the table of
// docs/formats.md, "Summaries", in that order; full_report() and the JSON
// conventions follow from it.
#include <catch2/catch.hpp>

#include "qpreduce/deform/deformer/deformer.h"
#include "qpreduce/deform/mesh/mesh_check.h"
#include "qpreduce/deform/pipeline/run_scenario.h"
#include "qpreduce/deform/proxies/clusters.h"
#include "qpreduce/deform/reference/reference.h"
#include "qpreduce/deform/refine/refine.h"

#include <qpreduce/full_solve.h>
#include <qpreduce/problems/schur_baseline.h>
#include <qpreduce/quotient.h>
#include <qpreduce/subspace.h>
#include <qpreduce/subspace_solver.h>
#include <qpreduce/theorem.h>
#ifdef QPREDUCE_HAVE_DISTRIBUTED
#include <qpreduce/distributed/mumps_subspace.h>
#endif

#include <algorithm>
#include <cmath>
#include <fstream>
#include <map>
#include <memory>
#include <regex>
#include <sstream>
#include <string>
#include <variant>
#include <vector>

using namespace qpreduce;
using namespace qpreduce::deform;

namespace {

std::vector<std::string> keys_of(const Outcome& summary) {
  std::vector<std::string> keys;
  const Report report = summary.report();  // (not a temporary in the loop's range: it would die first)
  for (const Report::Entry& e : report.entries()) keys.push_back(e.key);
  return keys;
}

// The "Summaries" table of docs/formats.md: summary name -> its keys after
// status and message ("those of `X`, then" expands X's).
std::map<std::string, std::vector<std::string>> documented_keys() {
  std::ifstream in(QPREDUCE_DOCS_DIR "/formats.md");
  REQUIRE(in.good());
  std::map<std::string, std::vector<std::string>> table;
  const std::regex row(R"(^\| `([A-Za-z]+Summary)` \| (.*) \|$)");
  const std::regex key("`([a-z_0-9]+)`");
  const std::regex base("those of `([A-Za-z]+Summary)`");
  std::string line;
  bool in_section = false;
  while (std::getline(in, line)) {
    if (line.rfind("## ", 0) == 0) in_section = line == "## Summaries";
    std::smatch m;
    if (!in_section || !std::regex_match(line, m, row)) continue;
    std::vector<std::string> keys;
    std::string cells = m[2];
    std::smatch b;
    if (std::regex_search(cells, b, base)) keys = table.at(b[1]);
    for (std::sregex_iterator it(cells.begin(), cells.end(), key), end; it != end; ++it) keys.push_back((*it)[1]);
    table[m[1]] = keys;
  }
  return table;
}

}  // namespace

TEST_CASE("every summary's report has the keys docs/formats.md lists, in order, after status and message") {
  const auto table = documented_keys();
  const std::vector<std::pair<std::string, std::shared_ptr<Outcome>>> summaries{
      {"SubspaceSummary", std::make_shared<SubspaceSummary>()},
      {"ConstraintSummary", std::make_shared<ConstraintSummary>()},
      {"FullSolveSummary", std::make_shared<FullSolveSummary>()},
      {"FactorSummary", std::make_shared<FactorSummary>()},
      {"TheoremSetupSummary", std::make_shared<TheoremSetupSummary>()},
      {"SchurBaselineSummary", std::make_shared<SchurBaselineSummary>()},
      {"SpectralSummary", std::make_shared<SpectralSummary>()},
      {"ClusterSummary", std::make_shared<ClusterSummary>()},
      {"PrecomputeSummary", std::make_shared<PrecomputeSummary>()},
      {"FrameSummary", std::make_shared<FrameSummary>()},
      {"ReferenceSummary", std::make_shared<ReferenceSummary>()},
      {"HandleSetSummary", std::make_shared<HandleSetSummary>()},
      {"RefineSummary", std::make_shared<RefineSummary>()},
      {"ScenarioRunSummary", std::make_shared<ScenarioRunSummary>()},
      {"MeshCheckSummary", std::make_shared<MeshCheckSummary>()},
#ifdef QPREDUCE_HAVE_DISTRIBUTED
      {"DistributedSummary", std::make_shared<distributed::DistributedSummary>()},
#endif
  };
  for (const auto& [name, summary] : summaries) {
    INFO(name);
    REQUIRE(table.count(name) == 1);
    std::vector<std::string> expected{"status", "message"};
    expected.insert(expected.end(), table.at(name).begin(), table.at(name).end());
    CHECK(keys_of(*summary) == expected);
  }
}

TEST_CASE("full_report prints every field, nested summaries indented, and brief_report dispatches") {
  PrecomputeSummary pre;
  pre.status = Status::Success;
  pre.vertices = 1234;
  pre.subspace.status = Status::Success;
  pre.subspace.n = 3702;
  pre.subspace.kkt_residual = 2.5e-13;
  const std::string text = pre.full_report();
  CHECK(text.rfind("status: success\nmessage: \nvertices: 1234\n", 0) == 0);
  CHECK(text.find("subspace:\n  status: success\n") != std::string::npos);
  CHECK(text.find("\n  n: 3702\n") != std::string::npos);
  CHECK(text.find("\n  kkt_residual: 2.5e-13\n") != std::string::npos);
  // One line per field and per nested field, plus the nested summary's own line.
  const auto lines = static_cast<size_t>(std::count(text.begin(), text.end(), '\n'));
  CHECK(lines == pre.report().entries().size() + pre.subspace.report().entries().size());

  // brief_report is virtual: a SubspaceSummary seen as an Outcome says more than its status.
  const Outcome& as_outcome = pre.subspace;
  CHECK(as_outcome.brief_report() == pre.subspace.brief_report());
  CHECK(as_outcome.brief_report() != Outcome(pre.subspace).brief_report());

  // Enums by name, non-finite reals kept as they are (the JSON writer makes them null).
  RefineSummary refine;
  const Report r = refine.report();
  CHECK(std::get<std::string>(*r.find("status")) == "not-run");
  CHECK(std::isinf(std::get<double>(*r.find("estimated_distance"))));
  FrameSummary frame;
  CHECK(std::get<std::string>(*frame.report().find("stop")) == to_string(frame.stop));
  CHECK(r.find("round_energy") == nullptr);
}
