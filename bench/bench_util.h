// Shared set-up for the engine benchmarks: the grid problems of
// docs/performance.md and a peak-memory probe. Bench-only; the seeded
// generators themselves live in qpreduce/generators.h.
#pragma once

#include "qpreduce/problems/generators.h"

#include <sys/resource.h>

#include <cstdint>
#include <fstream>
#include <sstream>
#include <string>

namespace qpreduce::bench {

// How the linear-term design space D (n × k) is built.
enum class DKind : int {
  Trend = 0,     // k = 10 smooth polynomial columns (grid_trend_basis), d = p − 10
  Gaussian = 1,  // k = p/2 i.i.d. Gaussian columns (dense), d = p − k
};

inline const char* to_string(DKind kind) { return kind == DKind::Trend ? "trend" : "gaussian"; }

// A side × side grid Laplacian (PSD, constants in its null space: no ridge),
// C = selection of d random vertices, D per DKind, and one demand that lies
// in the design spaces: A = the first m columns of C (point handles at m of
// the C vertices), b Gaussian, q = D·Y.
struct GridProblem {
  Index side = 0, n = 0, d = 0, k = 0, m = 0;
  SparseMatrix<double> H, C, D, A;
  Vector<double> b, Y, q;
};

inline GridProblem make_grid_problem(Index side, Index p, DKind kind, Index m, std::uint64_t seed = 1) {
  namespace gen = qpreduce::generators;
  GridProblem g;
  g.side = side;
  g.n = side * side;
  g.k = kind == DKind::Trend ? 10 : p / 2;
  g.d = p - g.k;
  g.m = m;
  g.H = gen::grid_laplacian_2d(side, side, 0.0);
  const std::vector<Index> rows = gen::random_subset(g.n, g.d, seed);
  g.C = gen::selection(g.n, rows);
  g.D = kind == DKind::Trend ? gen::grid_trend_basis(side, side, g.k) : gen::gaussian_sparse(g.n, g.k, seed + 1);
  if (m > 0) g.A = gen::selection(g.n, std::vector<Index>(rows.begin(), rows.begin() + m));
  g.b = gen::gaussian_vector(m, seed + 2);
  g.Y = gen::gaussian_vector(g.k, seed + 3);
  g.q = g.D * g.Y;
  return g;
}

// Peak resident memory. Linux lets a process reset its high-water mark
// (VmHWM) by writing "5" to /proc/self/clear_refs; where that fails, the
// lifetime maximum of getrusage(ru_maxrss) is reported instead and
// `resettable()` says so.
class PeakMemory {
 public:
  // Resets the high-water mark to the current resident size.
  void reset() {
    std::ofstream f("/proc/self/clear_refs");
    f << "5";
    f.flush();
    resettable_ = static_cast<bool>(f);
    baseline_mb_ = status_mb("VmRSS:");
  }
  // Peak resident size in MiB since reset().
  double peak_mb() const {
    const double hwm = status_mb("VmHWM:");
    if (resettable_ && hwm > 0) return hwm;
    rusage u{};
    getrusage(RUSAGE_SELF, &u);
    return static_cast<double>(u.ru_maxrss) / 1024.0;
  }
  // Resident size in MiB at reset().
  double baseline_mb() const { return baseline_mb_; }
  bool resettable() const { return resettable_; }

 private:
  static double status_mb(const char* key) {
    std::ifstream f("/proc/self/status");
    std::string line;
    while (std::getline(f, line)) {
      if (line.rfind(key, 0) == 0) {
        std::istringstream in(line.substr(std::char_traits<char>::length(key)));
        double kb = 0;
        in >> kb;
        return kb / 1024.0;
      }
    }
    return -1.0;
  }
  bool resettable_ = false;
  double baseline_mb_ = 0.0;
};

}  // namespace qpreduce::bench
