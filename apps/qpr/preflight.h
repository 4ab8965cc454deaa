// qpr — the mesh pre-flight: the plugin's diagnose_mesh (mesh_check.h) run
// on a loaded scenario before anything is precomputed, and its findings as
// console lines and JSON. Shared by `qpr check` and by the commands that
// precompute on a user's mesh (deform, compare, view: load_scenario).
//
// --strict has the meaning it has elsewhere in qpr: a warning becomes an
// error. The status is then "errors" whenever there is a warning.
#pragma once

#include <qpreduce/deform/io/scenario.h>
#include <qpreduce/deform/mesh/mesh_check.h>

#include <nlohmann/json.hpp>

#include <cstdio>
#include <string>

namespace qpr {

// "clean", "warnings" or "errors", with --strict applied.
std::string check_status(const qpreduce::deform::MeshCheckSummary& summary, bool strict);

// Everything diagnose_mesh found, for a report: status (with --strict),
// counts, scale, and per finding its defect, severity, count, first
// offenders and message.
nlohmann::json check_json(const qpreduce::deform::MeshCheckSummary& summary, bool strict);

// One line per finding, "<indent><severity>: <message>" (severity "error"
// for a warning under --strict).
void print_findings(std::FILE* out, const qpreduce::deform::MeshCheckSummary& summary, bool strict,
                    const char* indent);

// Diagnoses the scenario's mesh with its handles as anchors. Throws
// std::invalid_argument "<name>: <the first error>" (under --strict also for
// a warning), naming how many more problems there are; otherwise prints the
// warnings to stderr and returns check_json of the findings.
nlohmann::json preflight(const qpreduce::deform::Scenario& scenario, const std::string& name, bool strict);

}  // namespace qpr
