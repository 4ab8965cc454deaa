#include "reports.h"

#include <qpreduce/util/atomic_file.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <type_traits>
#include <utility>
#include <variant>

namespace qpr {

double median(std::vector<double> samples) {
  if (samples.empty()) return 0.0;
  std::sort(samples.begin(), samples.end());
  const size_t h = samples.size() / 2;
  return samples.size() % 2 ? samples[h] : 0.5 * (samples[h - 1] + samples[h]);
}

double upper_median(std::vector<double> samples) {
  if (samples.empty()) return 0.0;
  std::sort(samples.begin(), samples.end());
  return samples[samples.size() / 2];
}

nlohmann::json finite_or_null(double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr); }

nlohmann::json to_json(const qpreduce::Report& report) {
  nlohmann::json out = nlohmann::json::object();
  for (const qpreduce::Report::Entry& e : report.entries()) {
    std::visit(
        [&](const auto& v) {
          using T = std::decay_t<decltype(v)>;
          if constexpr (std::is_same_v<T, double>) {
            out[e.key] = finite_or_null(v);
          } else if constexpr (std::is_same_v<T, std::vector<double>>) {
            nlohmann::json list = nlohmann::json::array();
            for (const double x : v) list.push_back(finite_or_null(x));
            out[e.key] = std::move(list);
          } else if constexpr (std::is_same_v<T, std::shared_ptr<const qpreduce::Report>>) {
            out[e.key] = to_json(*v);
          } else {
            out[e.key] = v;
          }
        },
        e.value);
  }
  return out;
}

nlohmann::json refine_json(const qpreduce::deform::RefineSummary& summary,
                           const qpreduce::deform::RefineOptions& options) {
  nlohmann::json r = to_json(summary.report());
  r["distance_tolerance"] = options.distance_tolerance;
  r["tolerance"] = options.tolerance;
  r["anderson_window"] = options.anderson_window;
  r["newton_after"] = options.newton_after;
  return r;
}

void write_json(const std::string& path, const nlohmann::json& doc, const std::string& what) {
  try {
    qpreduce::write_file_atomically(path, doc.dump(2) + "\n");
  } catch (const qpreduce::FileError& e) {
    throw qpreduce::FileError(path, 0, "cannot write the " + what + ": " + e.problem());
  }
}

}  // namespace qpr
