// qpr — the full-space finish of a reduced pose (`qpr deform --refine`,
// `qpr compare --convergence`). No math here: the plugin's Refiner works,
// this file parses the options, reports and prints.
#pragma once

#include <qpreduce/deform/io/scenario.h>
#include <qpreduce/deform/refine/refine.h>

#include <nlohmann/json.hpp>

#include <optional>

namespace CLI {
class App;
}

namespace qpr {

// --refine[=D] and the Anderson settings of the refine.
struct RefineArgs {
  // Set: refine, to RefineOptions::distance_tolerance D (the flag alone: its default).
  std::optional<double> tolerance;
  int anderson_window = 5;
  bool plain = false;  // --refine-plain: no Anderson acceleration
  int newton_after = qpreduce::deform::RefineOptions{}.newton_after;  // --refine-newton-after
};

// Registers --refine, --refine-anderson, --refine-plain and --refine-newton-after on `cmd`.
void add_refine_options(CLI::App* cmd, RefineArgs* args);

// The plugin's options for these arguments. Throws std::invalid_argument on
// a negative tolerance or a window outside [1, 16].
qpreduce::deform::RefineOptions refine_options(const RefineArgs& args);

// The console table's line for a report's "refine" object (refine_json).
void print_refine_line(const nlohmann::json& refine);

// Rounds and seconds of full-space classic ARAP from the reduced pose and
// from rest, plain and accelerated (window), each to `tolerance` (at most
// max_rounds rounds): to converge, and to come within `gap` (relative) of
// the lowest energy any run reached. Returns the report's "convergence"
// object; prints a table.
nlohmann::json convergence_study(const qpreduce::deform::Scenario& scenario, const qpreduce::deform::Vertices& reduced,
                                 const qpreduce::deform::RefineOptions& options, double gap);

}  // namespace qpr
