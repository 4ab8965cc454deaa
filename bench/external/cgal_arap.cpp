// CGAL's Surface_mesh_deformation (spokes-and-rims ARAP) on one edit, timed:
// the rounds and the wall time until the pose is within 1 % and 0.1 % of the
// bounding-box diagonal (RMS over the vertices) of a reference shape. The
// CGAL counterpart of libigl_arap.cpp, for the side-by-side of
// docs/performance.md ("Coming from libigl or CGAL: the same edit timed").
// CGAL is not a dependency of qpreduce, so this file is not part of the
// build. With Debian's libcgal-dev (CGAL 5.5, header-only) and Eigen:
//
//   g++ -std=c++17 -O3 -DNDEBUG -DCGAL_EIGEN3_ENABLED -isystem /usr/include/eigen3 \
//       bench/external/cgal_arap.cpp -o /tmp/cgal_arap -lgmp -lmpfr -pthread
//   /tmp/cgal_arap MESH.off B.txt BC.txt REFERENCE.off [--max-rounds N] [--out U.off]
//
// The same files as libigl_arap.cpp (scripts/libigl_side_by_side.py writes
// them): B.txt one vertex index per line (0-based), BC.txt one "x y z" per
// line in B's order, REFERENCE.off the converged shape (same vertex order).
// Every vertex is in the region of interest, the vertices of B are its
// control vertices; one deform(1, 0) call is one round.

#include <CGAL/Simple_cartesian.h>
#include <CGAL/Surface_mesh.h>
#include <CGAL/Surface_mesh_deformation.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <string>
#include <vector>

using Kernel = CGAL::Simple_cartesian<double>;
using Point = Kernel::Point_3;
using Mesh = CGAL::Surface_mesh<Point>;
using Vertex = Mesh::Vertex_index;
using Deformation = CGAL::Surface_mesh_deformation<Mesh, CGAL::Default, CGAL::Default, CGAL::SPOKES_AND_RIMS>;

namespace {

bool read_off(const char* path, Mesh* mesh) {
  std::ifstream in(path);
  return in && CGAL::IO::read_OFF(in, *mesh) && !mesh->is_empty();
}

// RMS over the vertices of |p_i − r_i|, over the diagonal.
double rms(const Mesh& m, const Mesh& r, double diag) {
  double sum = 0.0;
  for (Vertex v : m.vertices()) sum += CGAL::squared_distance(m.point(v), r.point(v));
  return std::sqrt(sum / static_cast<double>(m.number_of_vertices())) / diag;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 5) {
    std::fprintf(stderr, "usage: %s MESH.off B.txt BC.txt REFERENCE.off [--max-rounds N] [--out U.off]\n", argv[0]);
    return 2;
  }
  int max_rounds = 20000;
  std::string out;
  for (int i = 5; i + 1 < argc; i += 2) {
    if (std::string(argv[i]) == "--max-rounds") max_rounds = std::atoi(argv[i + 1]);
    if (std::string(argv[i]) == "--out") out = argv[i + 1];
  }
  Mesh mesh, ref;
  if (!read_off(argv[1], &mesh) || !read_off(argv[4], &ref) || ref.number_of_vertices() != mesh.number_of_vertices()) {
    std::fprintf(stderr, "cannot read %s and %s as OFF meshes with the same vertices\n", argv[1], argv[4]);
    return 1;
  }
  std::vector<int> b;
  std::vector<double> bc;
  {
    std::ifstream in(argv[2]);
    for (int i; in >> i;) b.push_back(i);
    std::ifstream in2(argv[3]);
    for (double x; in2 >> x;) bc.push_back(x);
  }
  if (bc.size() != 3 * b.size()) {
    std::fprintf(stderr, "%s has %zu numbers, expected 3 × %zu\n", argv[3], bc.size(), b.size());
    return 1;
  }
  double lo[3] = {1e300, 1e300, 1e300}, hi[3] = {-1e300, -1e300, -1e300};
  for (Vertex v : mesh.vertices())
    for (int c = 0; c < 3; ++c) {
      lo[c] = std::min(lo[c], mesh.point(v)[c]);
      hi[c] = std::max(hi[c], mesh.point(v)[c]);
    }
  const double diag = std::sqrt((hi[0] - lo[0]) * (hi[0] - lo[0]) + (hi[1] - lo[1]) * (hi[1] - lo[1]) +
                                (hi[2] - lo[2]) * (hi[2] - lo[2]));
  using clock = std::chrono::steady_clock;
  auto t0 = clock::now();
  Deformation deformation(mesh);
  deformation.insert_roi_vertices(mesh.vertices().begin(), mesh.vertices().end());
  for (int i : b) deformation.insert_control_vertex(Vertex(static_cast<Mesh::size_type>(i)));
  if (!deformation.preprocess()) {
    std::fprintf(stderr, "CGAL's preprocess failed (the system could not be factored)\n");
    return 1;
  }
  for (std::size_t i = 0; i < b.size(); ++i)
    deformation.set_target_position(Vertex(static_cast<Mesh::size_type>(b[i])),
                                    Point(bc[3 * i], bc[3 * i + 1], bc[3 * i + 2]));
  const double pre = std::chrono::duration<double>(clock::now() - t0).count();
  std::printf("n = %zu, |b| = %zu, CGAL %s Surface_mesh_deformation, SPOKES_AND_RIMS\n",
              static_cast<std::size_t>(mesh.number_of_vertices()), b.size(), CGAL_VERSION_STR);
  std::printf("preprocess %.3f s\n", pre);
  double solve = 0.0;
  bool one = false;
  for (int round = 1; round <= max_rounds; ++round) {
    t0 = clock::now();
    deformation.deform(1, 0.0);
    solve += std::chrono::duration<double>(clock::now() - t0).count();
    const double d = rms(mesh, ref, diag);
    if (!one && d <= 1e-2) {
      std::printf("1 %%: %d rounds, deform %.3f s, with the preprocess %.3f s\n", round, solve, pre + solve);
      one = true;
    }
    if (d <= 1e-3) {
      std::printf("0.1 %%: %d rounds, deform %.3f s, with the preprocess %.3f s (%.1f ms a round)\n", round, solve,
                  pre + solve, 1e3 * solve / round);
      if (!out.empty()) CGAL::IO::write_OFF(out, mesh, CGAL::parameters::stream_precision(17));
      return 0;
    }
    if (round % 500 == 0) std::printf("  %d rounds: RMS %.3e, %.3f s\n", round, d, solve);
  }
  std::printf("not within 0.1 %% after %d rounds (%.3f s, %.1f ms a round)\n", max_rounds, solve,
              1e3 * solve / max_rounds);
  if (!out.empty()) CGAL::IO::write_OFF(out, mesh, CGAL::parameters::stream_precision(17));
  return 0;
}
