#include "preflight.h"

#include "reports.h"

#include <fmt/format.h>

#include <stdexcept>

namespace qpr {

using namespace qpreduce::deform;

std::string check_status(const MeshCheckSummary& s, bool strict) {
  if (s.has_errors() || (strict && s.has_warnings())) return "errors";
  return s.has_warnings() ? "warnings" : "clean";
}

namespace {

CheckSeverity shown_severity(const MeshFinding& f, bool strict) { return strict ? CheckSeverity::Error : f.severity; }

nlohmann::json point(const Eigen::Vector3d& x) {
  return {finite_or_null(x(0)), finite_or_null(x(1)), finite_or_null(x(2))};
}

}  // namespace

nlohmann::json check_json(const MeshCheckSummary& s, bool strict) {
  nlohmann::json j;
  j["status"] = check_status(s, strict);
  j["strict"] = strict;
  j["vertices"] = s.vertices;
  j["elements"] = s.elements;
  j["element_type"] = s.corners == 4 ? "tet" : "triangle";
  j["components"] = s.components;
  j["anchors_checked"] = s.anchors_checked;
  j["scale"] = {{"bounding_box_min", point(s.box_min)},
                {"bounding_box_max", point(s.box_max)},
                {"diagonal", finite_or_null(s.diagonal)},
                {"shortest_edge", finite_or_null(s.shortest_edge)},
                {"longest_edge", finite_or_null(s.longest_edge)},
                {"worst_quality", finite_or_null(s.worst_quality)}};
  j["findings"] = nlohmann::json::array();
  int errors = 0, warnings = 0;
  for (const MeshFinding& f : s.findings) {
    const CheckSeverity severity = shown_severity(f, strict);
    (severity == CheckSeverity::Error ? errors : warnings) += 1;
    j["findings"].push_back({{"defect", to_string(f.defect)},
                             {"severity", to_string(severity)},
                             {"count", f.count},
                             {"item", f.item},
                             {"first", f.first},
                             {"message", f.message}});
  }
  j["errors"] = errors;
  j["warnings"] = warnings;
  j["seconds"] = s.seconds;
  return j;
}

void print_findings(std::FILE* out, const MeshCheckSummary& s, bool strict, const char* indent) {
  for (const MeshFinding& f : s.findings)
    fmt::print(out, "{}{}: {}\n", indent, to_string(shown_severity(f, strict)), f.message);
}

nlohmann::json preflight(const Scenario& sc, const std::string& name, bool strict) {
  const DeformableMesh& m = sc.model;
  const MeshCheckSummary s =
      m.is_tet() ? diagnose_mesh(m.V, m.T, anchored_vertices(sc)) : diagnose_mesh(m.V, m.F, anchored_vertices(sc));
  const MeshFinding* stop = s.first(CheckSeverity::Error);
  if (!stop && strict) stop = s.first(CheckSeverity::Warning);
  if (stop) {
    const size_t more = s.findings.size() - 1;
    throw std::invalid_argument(
        fmt::format("{}: {}{}{}", name, strict && stop->severity == CheckSeverity::Warning ? "(--strict) " : "",
                    stop->message,
                    more == 0 ? "" : fmt::format(" (and {} more problem{}: `qpr check` lists them)", more,
                                                 more == 1 ? "" : "s")));
  }
  for (const MeshFinding& f : s.findings) fmt::print(stderr, "  warning: {}: {}\n", name, f.message);
  return check_json(s, strict);
}

}  // namespace qpr
