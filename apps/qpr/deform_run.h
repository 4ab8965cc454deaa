// qpr — running a deformation scenario and reporting it (shared by `qpr demo`
// and `qpr deform`). No math here: the plugin does the work, this file times
// it, prints the table and writes the meshes and the JSON report.
#pragma once

#include <qpreduce/deform/scenario.h>

#include <nlohmann/json.hpp>

#include <string>
#include <vector>

namespace qpr {

struct RunSettings {
  qpreduce::deform::DeformerOptions options;
  // Meshes written: every frame in `write_frames` (0-based; −1 = the last).
  std::vector<int> write_frames{-1};
  std::string out_path;     // the last frame's mesh (or a pattern with {frame})
  std::string report_path;  // JSON report, optional
  bool progress = true;     // progress bar on stderr during precompute
  std::string name;         // what is deformed, for the table
};

// Precomputes, sets the handles, runs every frame of the scenario, prints a
// timing table to stdout and returns the report (also written to
// settings.report_path when set). Throws on bad input or a failed precompute.
nlohmann::json run_scenario(const qpreduce::deform::Scenario& scenario, const qpreduce::deform::TriangleMesh* surface,
                            const qpreduce::deform::TetMesh* solid, const RunSettings& settings);

// Peak resident set size of this process so far, in MB (getrusage).
double peak_rss_mb();

}  // namespace qpr
