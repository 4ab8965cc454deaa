// `qpr theorem` — Theorem 4.10 on seeded trials (docs/theorem.md).
//
// For every trial: the exact solution X_min of Eq. 1 (dense KKT), the engine's
// reduced answer X* (SubspaceSolver), the true error d_H(X*, X_min), the
// bound of Eq. 39 and η = bound / error. Trials run in groups that share
// (family, size, seed) and sweep ε, so H is factored once per group.
#include "reports.h"
#include "commands.h"
#include "guard.h"
#include "validators.h"

#include <qpreduce/util/atomic_file.h>
#include <qpreduce/problems/generators.h>
#include <qpreduce/util/timer.h>
#include <qpreduce/theorem.h>

#include <CLI/CLI.hpp>
#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <map>
#include <memory>
#include <string>
#include <utility>
#include <vector>

namespace qpr {

namespace {

namespace gen = qpreduce::generators;
using qpreduce::TheoremStatus;

// The ε sweep of every group: 0 (exact reproduction) then six decades.
const std::vector<double> kEpsilons = {0.0, 1e-6, 1e-5, 1e-4, 1e-3, 1e-2, 3e-2, 0.1, 0.3, 1.0};
// Requested sizes, cycled over groups (grids round to s² or s³ vertices).
const std::vector<qpreduce::Index> kSizes = {40, 64, 100, 150};

// The most trials one run accepts: every trial's record is kept for --csv
// (a few hundred bytes each), and a million take hours already.
constexpr int kMaxTrials = 1000000;

// The subcommand's help line.
constexpr const char* kTheoremAbout =
    "Check the error bound of Theorem 4.10 on seeded trials (families × ε). Exit code 1 if the bound is violated, "
    "2 if a trial failed, 3 if an output file cannot be written.";

struct TheoremOptions {
  int trials = 200;
  std::uint64_t seed = 1;
  std::string json, csv;
};

struct Record {
  gen::TheoremFamily family{};
  qpreduce::Index size = 0, n = 0, d = 0, k = 0, m = 0, nullity = 0;
  double epsilon = 0.0;
  std::uint64_t seed = 0;
  qpreduce::TheoremCheck check;
};

struct Stats {
  int trials = 0, applies = 0, not_applicable = 0, failed = 0;
  int violations = 0, theorem_violations = 0, refined_violations = 0;
  // Trials whose design spaces contain ker H (the engine's answer is then
  // covered by the bound), and those among them where d_H(X*, X_min) exceeded
  // the error of Eq. 35 (must not happen: X* is the d_H-best feasible point).
  int covered = 0, galerkin_violations = 0;
  double exact_max_rel_error = 0.0, exact_max_dh_rel_error = 0.0;
  std::vector<double> eta;  // bound / error, ε > 0 and theorem applicable

  void add(const Record& r) {
    const qpreduce::TheoremCheck& c = r.check;
    ++trials;
    if (c.status == TheoremStatus::SolveFailed || c.status == TheoremStatus::RankDeficientA ||
        c.status == TheoremStatus::IndefiniteH) {
      ++failed;
      return;
    }
    if (r.epsilon == 0.0) {
      exact_max_rel_error = std::max(exact_max_rel_error, c.practical_rel_error);
      if (c.exact_norm > 0.0) exact_max_dh_rel_error = std::max(exact_max_dh_rel_error, c.practical_error / c.exact_norm);
    }
    if (c.status == TheoremStatus::DoesNotApply) {
      ++not_applicable;
      return;
    }
    ++applies;
    if (c.practical_covered) {
      ++covered;
      galerkin_violations += c.theorem_error >= 0.0 && c.practical_error > c.theorem_error + c.slack;
    }
    violations += c.practical_violation();
    theorem_violations += c.theorem_violation();
    refined_violations += c.theorem_error > c.bound.refined_bound + c.slack;
    if (r.epsilon > 0.0 && c.practical_error > 0.0) eta.push_back(c.eta());
  }
  double eta_quantile(double p) const {
    if (eta.empty()) return std::nan("");
    std::vector<double> s = eta;
    std::sort(s.begin(), s.end());
    const double pos = p * static_cast<double>(s.size() - 1);
    const size_t i = static_cast<size_t>(pos);
    const double frac = pos - static_cast<double>(i);
    return i + 1 < s.size() ? s[i] * (1 - frac) + s[i + 1] * frac : s[i];
  }
  double eta_min() const { return eta.empty() ? std::nan("") : *std::min_element(eta.begin(), eta.end()); }
  double eta_max() const { return eta.empty() ? std::nan("") : *std::max_element(eta.begin(), eta.end()); }
};

// SplitMix64 of (seed, group): the problem seed of a group.
std::uint64_t group_seed(std::uint64_t seed, std::uint64_t group) {
  std::uint64_t z = seed * 0x9E3779B97F4A7C15ull + group + 1;
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}

nlohmann::json stats_json(const Stats& s) {
  return {{"trials", s.trials},
          {"applies", s.applies},
          {"not_applicable", s.not_applicable},
          {"failed", s.failed},
          {"violations", s.violations},
          {"theorem_violations", s.theorem_violations},
          {"refined_violations", s.refined_violations},
          {"covered_trials", s.covered},
          {"galerkin_violations", s.galerkin_violations},
          {"eta_count", s.eta.size()},
          {"eta_min", finite_or_null(s.eta_min())},
          {"eta_median", finite_or_null(s.eta_quantile(0.5))},
          {"eta_max", finite_or_null(s.eta_max())},
          {"exact_max_rel_error", s.exact_max_rel_error},
          {"exact_max_dh_rel_error", s.exact_max_dh_rel_error}};
}

bool write_text(const std::string& path, const std::string& text) {
  try {
    qpreduce::write_file_atomically(run_files().stage(path), text);
  } catch (const qpreduce::FileError& e) {
    fmt::print(stderr, "qpr theorem: error: {}\n", run_files().plain(e.what()));
    return false;
  }
  return true;
}

std::string csv_table(const std::vector<Record>& records) {
  std::string s =
      "family,size,n,d,k,m,nullity,epsilon,seed,status,error,theorem_error,bound,refined_bound,eta,rho,omega,"
      "q_residual,A_residual,exact_rel_error,practical_gap,covered,violation,theorem_violation,seconds\n";
  for (const Record& r : records) {
    const qpreduce::TheoremCheck& c = r.check;
    s += fmt::format("{},{},{},{},{},{},{},{:.3g},{},{},{:.6e},{:.6e},{:.6e},{:.6e},{:.6e},{:.6e},{:.6e},{:.6e},{:.6e},"
                     "{:.6e},{:.6e},{},{},{},{:.6f}\n",
                     gen::to_string(r.family), r.size, r.n, r.d, r.k, r.m, r.nullity, r.epsilon, r.seed,
                     qpreduce::to_string(c.status), c.practical_error, c.theorem_error, c.bound.bound,
                     c.bound.refined_bound, c.eta(), c.bound.rho, c.bound.omega, c.bound.q_residual,
                     c.bound.A_residual, c.practical_rel_error, c.practical_gap, int(c.practical_covered),
                     int(c.practical_violation()),
                     int(c.theorem_violation()), c.seconds);
  }
  return s;
}

// The trials: groups over (family, size, seed), each sweeping kEpsilons with
// one checker (H factored once). `first_failure` names the first failed trial.
std::vector<Record> run_trials(const TheoremOptions& opt, const std::vector<gen::TheoremFamily>& families,
                               std::string* first_failure) {
  std::vector<Record> records;  // grows with the trials run (a huge --trials must not reserve up front)
  const int per_group = static_cast<int>(kEpsilons.size());
  for (int g = 0; static_cast<int>(records.size()) < opt.trials; ++g) {
    const gen::TheoremFamily family = families[static_cast<size_t>(g) % families.size()];
    const qpreduce::Index size = kSizes[static_cast<size_t>(g / static_cast<int>(families.size())) % kSizes.size()];
    const std::uint64_t seed = group_seed(opt.seed, static_cast<std::uint64_t>(g));
    gen::TheoremTrial t = gen::theorem_problem(family, size, 0.0, seed);
    qpreduce::TheoremChecker checker;
    const qpreduce::TheoremSetupSummary setup = checker.precompute(t.H, t.C, t.D);
    for (int e = 0; e < per_group && static_cast<int>(records.size()) < opt.trials; ++e) {
      Record r;
      r.family = family;
      r.size = size;
      r.seed = seed;
      r.epsilon = kEpsilons[static_cast<size_t>(e)];
      r.n = t.n(), r.d = t.d(), r.k = t.k(), r.m = t.m(), r.nullity = t.kernel.cols();
      if (!setup.ok()) {
        r.check.status = setup.status == qpreduce::Status::IndefiniteH ? TheoremStatus::IndefiniteH
                                                                        : TheoremStatus::SolveFailed;
        r.check.message = setup.message;
      } else {
        t.set_epsilon(r.epsilon);
        r.check = checker.check(t.A, t.b, t.q);
      }
      if (first_failure->empty() && (r.check.status == TheoremStatus::SolveFailed ||
                                     r.check.status == TheoremStatus::RankDeficientA ||
                                     r.check.status == TheoremStatus::IndefiniteH)) {
        *first_failure = fmt::format("theorem_problem({}, {}, {}, {}): {}", gen::to_string(family), size, r.epsilon,
                                     seed, r.check.message);
      }
      records.push_back(std::move(r));
    }
  }
  return records;
}

// The summary table per family and overall (stdout).
void print_table(const TheoremOptions& opt, const std::vector<gen::TheoremFamily>& families,
                 std::map<gen::TheoremFamily, Stats>& by_family, const Stats& all, double seconds) {
  std::string eps_list;
  for (double e : kEpsilons) eps_list += (eps_list.empty() ? "" : ", ") + fmt::format("{:g}", e);
  fmt::print("Theorem 4.10 on {} seeded trials (seed {}), ε ∈ {{{}}}, {:.1f} s\n\n", all.trials, opt.seed, eps_list,
             seconds);
  fmt::print("{:<14} {:>6} {:>5} {:>6} {:>8} {:>10} {:>9} {:>9} {:>9} {:>14}\n", "family", "trials", "n.a.",
             "failed", "covered", "violations", "η min", "η median", "η max", "exact rel err");
  auto row = [](const std::string& name, const Stats& s) {
    const std::string covered = s.covered == s.applies ? "yes" : s.covered == 0 ? "no" : fmt::format("{}", s.covered);
    fmt::print("{:<14} {:>6} {:>5} {:>6} {:>8} {:>10} {:>9.3g} {:>9.3g} {:>9.3g} {:>14.2e}\n", name, s.trials,
               s.not_applicable, s.failed, covered, s.violations, s.eta_min(), s.eta_quantile(0.5), s.eta_max(),
               s.exact_max_rel_error);
  };
  for (gen::TheoremFamily f : families)
    if (by_family.count(f)) row(gen::to_string(f), by_family[f]);
  row("all", all);
  fmt::print(
      "\nerror = d_H(X*, X_min) with X* the engine's reduced answer; bound = Eq. 39; η = bound/error over\n"
      "trials with ε > 0 where the theorem applies (ρ < 1; \"n.a.\": ρ ≥ 1). \"exact rel err\": max ‖X* − X_min‖/‖X_min‖\n"
      "at ε = 0. Violations: error > bound + round-off. \"covered\": ker H ⊆ Span(C) + Span(D), so that\n"
      "d_H(X*, X_min) ≤ ‖X̂*_min − X̂_min‖ ≤ bound is a theorem (failed {} times); otherwise (dense-psd) the bound\n"
      "holding for X* is only an observation. The theorem's own reduced solution (Eq. 35) violated the bound\n"
      "{} times, our a-posteriori bound {} times.\n",
      all.galerkin_violations, all.theorem_violations, all.refined_violations);
}

// --json, --csv; false when one could not be written.
bool write_files(const TheoremOptions& opt, const std::vector<Record>& records,
                 const std::vector<gen::TheoremFamily>& families, std::map<gen::TheoremFamily, Stats>& by_family,
                 const Stats& all, double seconds) {
  bool written = true;
  if (!opt.json.empty()) {
    nlohmann::json j = stats_json(all);
    j["command"] = "qpr theorem";
    j["seed"] = opt.seed;
    j["epsilons"] = kEpsilons;
    j["sizes"] = kSizes;
    j["roundoff_factor"] = qpreduce::QuotientOptions{}.roundoff_factor;
    j["seconds"] = seconds;
    nlohmann::json fam = nlohmann::json::object();
    for (gen::TheoremFamily f : families)
      if (by_family.count(f)) fam[gen::to_string(f)] = stats_json(by_family[f]);
    j["families"] = fam;
    written = write_text(opt.json, j.dump(2) + "\n") && written;
  }
  if (!opt.csv.empty()) written = write_text(opt.csv, csv_table(records)) && written;
  return written;
}

int run_theorem(const TheoremOptions& opt) {
  // The outputs are checked before the trials, which may run for hours.
  try {
    for (const auto& [path, what] : {std::pair{&opt.json, "--json"}, {&opt.csv, "--csv"}})
      if (!path->empty()) qpreduce::check_destination(*path, what);
  } catch (const qpreduce::FileError& e) {
    fmt::print(stderr, "qpr theorem: error: {}\n", e.what());
    return 3;
  }
  const qpreduce::Timer timer;
  const std::vector<gen::TheoremFamily> families = gen::theorem_families();
  std::string first_failure;
  const std::vector<Record> records = run_trials(opt, families, &first_failure);

  Stats all;
  std::map<gen::TheoremFamily, Stats> by_family;
  for (const Record& r : records) {
    all.add(r);
    by_family[r.family].add(r);
  }
  const double seconds = timer.seconds();

  print_table(opt, families, by_family, all, seconds);
  if (!first_failure.empty()) fmt::print(stderr, "first failed trial: {}\n", first_failure);
  if (!write_files(opt, records, families, by_family, all, seconds)) return 3;
  if (all.violations > 0 || all.theorem_violations > 0) {
    fmt::print(stderr, "qpr theorem: {} violation(s) of the bound (see --csv for the trials)\n",
               all.violations + all.theorem_violations);
    return 1;
  }
  if (all.failed > 0) {
    fmt::print(stderr, "qpr theorem: {} trial(s) failed\n", all.failed);
    return 2;
  }
  return 0;
}

}  // namespace

void register_theorem(CLI::App& app) {
  auto [cmd, opt] = add_command<TheoremOptions>(app, "theorem", kTheoremAbout);
  cmd->add_option("--trials", opt->trials, "number of trials (groups of 10 values of ε share H, C, D)")
      ->check(whole_number_between(1, kMaxTrials))
      ->capture_default_str();
  cmd->add_option("--seed", opt->seed, "base seed of the trials")
      ->check(unsigned_whole_number())
      ->capture_default_str();
  add_path_option(cmd, PathRole::Output, "--json", opt->json, "write the summary (overall and per family) as JSON");
  add_path_option(cmd, PathRole::Output, "--csv", opt->csv, "write one row per trial as CSV (scripts/theorem_figure.py plots it)");
  cmd->callback([opt = opt] { run_guarded("theorem", [&] { return run_theorem(*opt); }, {1}); });
}

}  // namespace qpr
