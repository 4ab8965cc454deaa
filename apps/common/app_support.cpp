#include "app_support.h"

#include <qpreduce/atomic_file.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>

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

void write_json(const std::string& path, const nlohmann::json& doc, const std::string& what) {
  try {
    qpreduce::write_file_atomically(path, doc.dump(2) + "\n");
  } catch (const qpreduce::FileError& e) {
    throw qpreduce::FileError(path, 0, "cannot write the " + what + ": " + e.problem());
  }
}

}  // namespace qpr
