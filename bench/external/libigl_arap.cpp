// libigl's arap_precomputation + arap_solve on one edit, timed: the rounds
// and the wall time until the pose is within 1 % and 0.1 % of the bounding-box
// diagonal (RMS over the vertices) of a reference shape. For the side-by-side
// of docs/performance.md ("Coming from libigl or CGAL: the same edit timed"); libigl is
// not a dependency of qpreduce, so this file is not part of the build. With a
// libigl checkout's include/ folder (header-only use) and Debian's Eigen:
//
//   g++ -std=c++17 -O3 -DNDEBUG -I LIBIGL/include -isystem /usr/include/eigen3 \
//       bench/external/libigl_arap.cpp -o /tmp/libigl_arap -pthread
//   /tmp/libigl_arap MESH.off B.txt BC.txt REFERENCE.off [--max-rounds N] [--out U.off]
//
// B.txt: one vertex index per line (0-based); BC.txt: one "x y z" per line,
// in B's order; REFERENCE.off: the converged shape (same vertex order).
// scripts/libigl_side_by_side.py writes all three and runs it.

#include <igl/arap.h>
#include <igl/readOFF.h>
#include <igl/writeOFF.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <string>
#include <vector>

int main(int argc, char** argv) {
  if (argc < 5) {
    std::fprintf(stderr, "usage: %s MESH.off B.txt BC.txt REFERENCE.off [--max-rounds N] [--out U.off]\n", argv[0]);
    return 2;
  }
  int max_rounds = 20000;
  std::string out;  // the last pose, when asked
  for (int i = 5; i + 1 < argc; i += 2) {
    if (std::string(argv[i]) == "--max-rounds") max_rounds = std::atoi(argv[i + 1]);
    if (std::string(argv[i]) == "--out") out = argv[i + 1];
  }
  Eigen::MatrixXd V, R;
  Eigen::MatrixXi F, FR;
  if (!igl::readOFF(argv[1], V, F) || !igl::readOFF(argv[4], R, FR)) return 1;
  std::vector<int> bv;
  std::vector<double> bcv;
  {
    std::ifstream in(argv[2]);
    for (int i; in >> i;) bv.push_back(i);
    std::ifstream in2(argv[3]);
    for (double x; in2 >> x;) bcv.push_back(x);
  }
  Eigen::VectorXi b = Eigen::Map<Eigen::VectorXi>(bv.data(), static_cast<Eigen::Index>(bv.size()));
  Eigen::MatrixXd bc(b.size(), 3);
  for (Eigen::Index i = 0; i < b.size(); ++i)
    for (int c = 0; c < 3; ++c) bc(i, c) = bcv[static_cast<size_t>(3 * i + c)];
  const double diag = (V.colwise().maxCoeff() - V.colwise().minCoeff()).norm();
  using clock = std::chrono::steady_clock;
  auto t0 = clock::now();
  igl::ARAPData data;
  data.max_iter = 1;
  igl::arap_precomputation(V, F, 3, b, data);
  const double pre = std::chrono::duration<double>(clock::now() - t0).count();
  std::printf("n = %ld, |b| = %ld, libigl's default energy (spokes and rims for triangles in 3D)\n",
              static_cast<long>(V.rows()), static_cast<long>(b.size()));
  std::printf("arap_precomputation %.3f s\n", pre);
  Eigen::MatrixXd U = V;
  for (Eigen::Index i = 0; i < b.size(); ++i) U.row(b(i)) = bc.row(i);
  double solve = 0.0;
  bool one = false;
  for (int round = 1; round <= max_rounds; ++round) {
    t0 = clock::now();
    igl::arap_solve(bc, data, U);
    solve += std::chrono::duration<double>(clock::now() - t0).count();
    const double rms = std::sqrt((U - R).rowwise().squaredNorm().mean()) / diag;
    if (!one && rms <= 1e-2) {
      std::printf("1 %%: %d rounds, arap_solve %.3f s, with the precomputation %.3f s\n", round, solve, pre + solve);
      one = true;
    }
    if (rms <= 1e-3) {
      std::printf("0.1 %%: %d rounds, arap_solve %.3f s, with the precomputation %.3f s (%.1f ms a round)\n", round,
                  solve, pre + solve, 1e3 * solve / round);
      if (!out.empty()) igl::writeOFF(out, U, F);
      return 0;
    }
    if (round % 500 == 0) std::printf("  %d rounds: RMS %.3e, %.3f s\n", round, rms, solve);
  }
  std::printf("not within 0.1 %% after %d rounds (%.3f s, %.1f ms a round)\n", max_rounds, solve,
              1e3 * solve / max_rounds);
  if (!out.empty()) igl::writeOFF(out, U, F);
  return 0;
}
