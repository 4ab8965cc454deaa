#include "app_support.h"

#include <algorithm>
#include <cmath>
#include <fstream>
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
  std::ofstream out(path, std::ios::binary);
  out << doc.dump(2) << "\n";
  out.close();
  if (!out) throw std::runtime_error(path + ": cannot write the " + what);
}

}  // namespace qpr
