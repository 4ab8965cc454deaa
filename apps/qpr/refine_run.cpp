// qpr — `--refine` and `--convergence` (refine_run.h).
#include "refine_run.h"
#include "reports.h"
#include "validators.h"

#include <qpreduce/anderson.h>
#include <qpreduce/deform/mesh/geometry.h>

#include <CLI/CLI.hpp>
#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

namespace qpr {

using namespace qpreduce;
using namespace qpreduce::deform;

void add_refine_options(CLI::App* cmd, RefineArgs* a) {
  cmd->add_option_function<std::string>(
         "--refine",
         [a](const std::string& v) {
           if (v.empty()) {
             a->tolerance = RefineOptions{}.distance_tolerance;
             return;
           }
           double tol = 0.0;
           if (!CLI::detail::lexical_cast(v, tol) || !std::isfinite(tol) || tol < 0.0)
             throw CLI::ValidationError("--refine", "D must be a finite number ≥ 0, got '" + v + "'");
           a->tolerance = tol;
         },
         fmt::format("Refine the last frame's pose in full space (classic ARAP, local-global warm-started from the "
                     "reduced pose) until it is estimated to be within D of the converged shape (RMS over the "
                     "vertices, / the bounding-box diagonal; default {:g}; give D as --refine=D; 0: to the "
                     "reference test)",
                     RefineOptions{}.distance_tolerance))
      ->expected(0, 1)
      ->type_name("[D]");
  cmd->add_option("--refine-anderson", a->anderson_window, "Anderson window of the refine, 1-16 (default 5)")
      ->check(whole_number_between(1, 16));
  cmd->add_flag("--refine-plain", a->plain,
                "Refine with plain local-global rounds (no Anderson acceleration, no Newton steps)");
  cmd->add_option("--refine-newton-after", a->newton_after,
                  fmt::format("Rounds of the refine before Newton steps on the classic energy replace them; 0: rounds "
                              "only (default {})",
                              RefineOptions{}.newton_after))
      ->check(whole_number_between(0, 1000000));
}

RefineOptions refine_options(const RefineArgs& a) {
  RefineOptions o;
  o.distance_tolerance = a.tolerance.value_or(o.distance_tolerance);
  if (!(o.distance_tolerance >= 0.0) || !std::isfinite(o.distance_tolerance)) {
    throw std::invalid_argument(
        fmt::format("--refine: the distance must be finite and ≥ 0, got {}", o.distance_tolerance));
  }
  if (a.anderson_window < 1 || a.anderson_window > AndersonAcceleration::kMaxWindow) {
    throw std::invalid_argument(
        fmt::format("--refine-anderson must be in [1, {}], got {} (use --refine-plain for no acceleration)",
                    AndersonAcceleration::kMaxWindow, a.anderson_window));
  }
  o.anderson_window = a.plain ? 0 : a.anderson_window;
  if (a.newton_after < 0) throw std::invalid_argument(fmt::format("--refine-newton-after must be ≥ 0, got {}", a.newton_after));
  o.newton_after = a.plain ? 0 : a.newton_after;
  return o;
}

namespace {

// The first round whose energy is within `gap` of `best` (relative): rounds
// and seconds to reach it, or nulls when no round did. The starting pose
// counts (0 rounds) only when it meets the handles (not the rest pose, whose
// energy is 0).
nlohmann::json time_to_gap(const RefineSummary& s, bool from_rest, double best, double gap) {
  const double bar = best * (1 + gap);
  if (!from_rest && s.initial_energy <= bar) return {{"rounds", 0}, {"seconds", 0.0}};
  for (size_t i = 0; i < s.round_energy.size(); ++i)
    if (s.round_energy[i] <= bar) return {{"rounds", static_cast<int>(i + 1)}, {"seconds", s.round_seconds[i]}};
  return {{"rounds", nullptr}, {"seconds", nullptr}};
}

}  // namespace

void print_refine_line(const nlohmann::json& r) {
  const int window = r["anderson_window"].get<int>();
  fmt::print(
      "  {:<28}{:>12.3f} ms   ({} rounds{}{}, ARAP energy {:.5g} -> {:.5g}; from the reduced pose RMS {:.2e}, max {:.2e} "
      "of the diagonal; estimated {:.1e} from converged{})\n",
      "refine (full space)", 1e3 * r["seconds"].get<double>(), r["rounds"].get<int>(),
      window > 0 ? fmt::format(", Anderson {}", window) : std::string(", plain"),
      r.value("newton_steps", 0) > 0
          ? fmt::format(", {} of them Newton steps with {} CG products", r["newton_steps"].get<int>(),
                        r["cg_iterations"].get<int>())
          : std::string(),
      r["initial_energy"].get<double>(), r["arap_energy"].get<double>(), r["rms_from_input"].get<double>(),
      r["max_from_input"].get<double>(),
      r["estimated_distance"].is_null() ? std::numeric_limits<double>::infinity() : r["estimated_distance"].get<double>(),
      r["converged"].get<bool>() ? "" : "; not converged");
}

nlohmann::json convergence_study(const Scenario& scenario, const Vertices& reduced, const RefineOptions& options,
                                 double gap) {
  Refiner refiner;
  refiner.precompute(scenario.model, options);
  struct Run {
    const char* name;
    bool from_rest;
    int window;
    int newton_after;
    RefineSummary summary;
    Vertices pose;
  };
  const int window = std::max(1, options.anderson_window);
  const int newton = options.newton_after > 0 ? options.newton_after : RefineOptions{}.newton_after;
  std::vector<Run> runs{{"reduced_newton", false, window, newton, {}, {}},
                        {"reduced_anderson", false, window, 0, {}, {}},
                        {"reduced_plain", false, 0, 0, {}, {}},
                        {"rest_newton", true, window, newton, {}, {}},
                        {"rest_anderson", true, window, 0, {}, {}},
                        {"rest_plain", true, 0, 0, {}, {}}};
  double best = std::numeric_limits<double>::infinity();
  const Run* best_run = nullptr;
  for (Run& run : runs) {
    RefineOptions o = options;
    o.anderson_window = run.window;
    o.newton_after = run.newton_after;
    refiner.set_options(o);
    run.summary =
        refiner.refine(scenario.handles, scenario.frames.back(), run.from_rest ? Vertices() : reduced, &run.pose);
    if (!run.summary.usable())
      throw std::runtime_error(std::string("convergence: ") + run.name + ": " + run.summary.message);
    if (run.summary.arap_energy < best) {
      best = run.summary.arap_energy;
      best_run = &run;
    }
  }
  const double diag = bounding_box_diagonal(scenario.model.V);
  nlohmann::json c;
  c["tolerance"] = options.tolerance;
  c["max_rounds"] = options.max_iterations;
  c["anderson_window"] = window;
  c["gap"] = gap;
  c["converged_energy"] = best;
  c["converged_run"] = best_run->name;
  fmt::print("convergence of full-space classic ARAP (tolerance {:g}; gap {:g} to the lowest energy {:.8g}, {}):\n",
             options.tolerance, gap, best, best_run->name);
  fmt::print("  {:<18}{:>10}{:>12}{:>12}{:>12}{:>10}{:>14}\n", "", "rounds", "seconds", "to gap: rds", "seconds",
             "rejected", "RMS to best");
  for (const Run& run : runs) {
    nlohmann::json r = to_json(run.summary.report());
    r["to_gap"] = time_to_gap(run.summary, run.from_rest, best, gap);
    const Eigen::VectorXd d = (run.pose - best_run->pose).rowwise().norm();
    r["rms_from_converged"] = std::sqrt(d.squaredNorm() / static_cast<double>(d.size())) / diag;
    const auto& tg = r["to_gap"];
    fmt::print("  {:<18}{:>10}{:>12.3f}{:>12}{:>12}{:>10}{:>14.2e}{}\n", run.name, run.summary.rounds,
               run.summary.seconds, tg["rounds"].is_null() ? "-" : tg["rounds"].dump(),
               tg["seconds"].is_null() ? "-" : fmt::format("{:.3f}", tg["seconds"].get<double>()),
               run.summary.rejected_steps, r["rms_from_converged"].get<double>(),
               run.summary.converged ? "" : "  (round limit)");
    c[run.name] = r;
  }
  return c;
}

}  // namespace qpr
