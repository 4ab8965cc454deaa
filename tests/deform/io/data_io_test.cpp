// Every mesh and handle file of ../shared/data loads with the counts its
// README gives, and with the invariants the README states (outward
// orientation, positive tets, surface nodes of the TetGen solids equal to the
// surface vertices). Skips with a warning when ../shared is absent.
#include "io_test_util.h"

#include "qpreduce/deform/io/handles_io.h"
#include "qpreduce/deform/io/mesh_io.h"
#include "qpreduce/deform/io/tet_io.h"

#include <Eigen/Dense>

#include <algorithm>
#include <set>

using namespace qpreduce::deform;
using qpreduce::Index;

namespace {

// Σ_f det[a, b, c] / 6: positive for a closed surface with outward faces.
double signed_volume(const TriangleMesh& m) {
  double v = 0.0;
  for (Index f = 0; f < m.F.rows(); ++f) {
    Eigen::Matrix3d M;
    for (int k = 0; k < 3; ++k) M.col(k) = m.V.row(m.F(f, k)).transpose();
    v += M.determinant() / 6.0;
  }
  return v;
}

// min over tets of det[b − a, c − a, d − a].
double min_tet_det(const TetMesh& m) {
  double lo = std::numeric_limits<double>::infinity();
  for (Index t = 0; t < m.T.rows(); ++t) {
    Eigen::Matrix3d M;
    for (int k = 0; k < 3; ++k) M.col(k) = (m.V.row(m.T(t, k + 1)) - m.V.row(m.T(t, 0))).transpose();
    lo = std::min(lo, M.determinant());
  }
  return lo;
}

Index distinct_vertices(const Triangles& F) {
  return static_cast<Index>(std::set<int>(F.data(), F.data() + F.size()).size());
}

struct SurfaceCase {
  const char* path;
  Index vertices, faces;
  bool closed;
  Index unreferenced;
};

// From shared/data/README.md, paper-examples/README.md and references/README.md.
const SurfaceCase kSurfaces[] = {
    {"meshes/armadillo.obj", 43243, 86482, true, 0},
    {"meshes/bunny.off", 3485, 6966, true, 0},
    {"meshes/stanford-bunny.obj", 35947, 69451, false, 1113},
    {"meshes/decimated-knight.off", 502, 1000, true, 0},
    {"meshes/knight.off", 13336, 26668, true, 0},
    {"meshes/fertility.off", 4494, 9000, true, 0},
    {"meshes/dinosaur.obj", 14000, 27996, true, 0},
    {"meshes/xyzrgb-dragon.ply", 9994, 19984, true, 0},
    {"meshes/spot.obj", 2930, 5856, true, 0},
    {"meshes/ogre.obj", 62194, 124008, false, 0},
    {"meshes/botsch-sorkine/cylinder.off", 4802, 9600, true, 0},
    {"meshes/botsch-sorkine/cactus.off", 5261, 10518, true, 0},
    {"meshes/botsch-sorkine/bar.off", 6084, 12106, false, 0},
    {"meshes/botsch-sorkine/bumpy_plane.off", 40401, 80000, false, 0},
    {"meshes/botsch-sorkine/cylinder-laplacian_editing.off", 4802, 9600, true, 0},
    {"meshes/botsch-sorkine/cactus-laplacian_editing.off", 5261, 10518, true, 0},
    {"meshes/botsch-sorkine/bar-laplacian_editing.off", 6084, 12106, false, 0},
    {"meshes/botsch-sorkine/bumpy_plane-laplacian_editing.off", 40401, 80000, false, 0},
    {"paper-examples/dinosaur/dinosaur.off", 21074, 42144, false, 0},
    {"paper-examples/dragon/dragon.off", 52718, 105652, false, 0},
    {"paper-examples/tree/tree.off", 3630, 7346, false, 0},
    {"paper-examples/teapot/teapot.off", 10702, 21412, false, 0},
    {"paper-examples/test2/test2_arap1.off", 5261, 10518, false, 0},
    {"paper-examples/test2/test2_arap2.off", 5261, 10518, false, 0},
    {"references/cgal_sr_cylinder_it10000.off", 4802, 9600, true, 0},
    {"references/cgal_sr_cactus_it10000.off", 5261, 10518, true, 0},
    {"references/cgal_sr_bar_it10000.off", 6084, 12106, false, 0},
    {"references/cgal_sr_bumpy_plane_it5000.off", 40401, 80000, false, 0},
    {"references/cgal_sr_armadillo_it5000.off", 43243, 86482, true, 0},
    {"references/libigl_tet_solid_cylinder_it2000.off", 4802, 9600, true, 0},
};

struct TetCase {
  const char* path;
  Index vertices, tets, boundary_faces, boundary_vertices;
};

const TetCase kTets[] = {
    {"tets/solid_cylinder.node", 7924, 34105, 9600, 4802},
    {"tets/solid_cactus.ele", 6793, 24271, 10518, 5261},
    {"tets/solid_fertility.node", 25802, 151363, 9000, 4494},
    {"tets/hand.mesh", 7234, 29998, 9556, 4780},
    {"tets/octopus-low.mesh", 452, 1140, 898, 451},
};

}  // namespace

TEST_CASE("shared surface meshes load with the README counts", "[io][data]") {
  REQUIRE_SHARED_DATA(data);
  for (const SurfaceCase& c : kSurfaces) {
    INFO(c.path);
    MeshReadInfo info;
    const TriangleMesh m = read_triangle_mesh(data + "/" + c.path, &info);
    CHECK(m.V.rows() == c.vertices);
    CHECK(m.F.rows() == c.faces);
    CHECK(info.unreferenced_vertices == c.unreferenced);
    CHECK(info.polygons_triangulated == 0);
    if (c.closed) CHECK(signed_volume(m) > 0.0);
  }
}

TEST_CASE("shared tet meshes load with the README counts, all tets positive", "[io][data]") {
  REQUIRE_SHARED_DATA(data);
  for (const TetCase& c : kTets) {
    INFO(c.path);
    MeshReadInfo info;
    const TetMesh m = read_tet_mesh(data + "/" + c.path, &info);
    CHECK(m.V.rows() == c.vertices);
    CHECK(m.T.rows() == c.tets);
    CHECK(m.F.rows() == c.boundary_faces);
    CHECK(distinct_vertices(m.F) == c.boundary_vertices);
    CHECK(min_tet_det(m) > 0.0);
  }
}

TEST_CASE("TetGen solids start with their surface's vertices, in order, exactly", "[io][data]") {
  REQUIRE_SHARED_DATA(data);
  const std::pair<const char*, const char*> pairs[] = {
      {"tets/solid_cylinder.node", "meshes/botsch-sorkine/cylinder.off"},
      {"tets/solid_cactus.node", "meshes/botsch-sorkine/cactus.off"}};
  for (const auto& [solid_path, surface_path] : pairs) {
    INFO(solid_path);
    const TetMesh solid = read_tetgen(data + "/" + solid_path);
    const TriangleMesh surface = read_off(data + "/" + surface_path);
    CHECK(solid.V.topRows(surface.V.rows()) == surface.V);
    CHECK(solid.F.maxCoeff() < surface.V.rows());
  }
}

TEST_CASE("Botsch-Sorkine .sel and .def load and fit their meshes", "[io][data][handles]") {
  REQUIRE_SHARED_DATA(data);
  struct Case {
    const char* stem;
    Index n, fixed, free, handle;
  };
  const Case cases[] = {{"meshes/botsch-sorkine/cylinder", 4802, 241, 4320, 241},
                        {"meshes/botsch-sorkine/cactus", 5261, 446, 4397, 418},
                        {"meshes/botsch-sorkine/bar", 6084, 382, 5122, 580},
                        {"meshes/botsch-sorkine/bumpy_plane", 40401, 1809, 36984, 1608},
                        {"references/armadillo", 43243, 2163, 38917, 2163}};
  for (const Case& c : cases) {
    INFO(c.stem);
    const Selection sel = read_sel(data + "/" + c.stem + ".sel");
    CHECK_NOTHROW(sel.validate(c.n));
    CHECK(sel.count(SelRole::Fixed) == c.fixed);
    CHECK(sel.count(SelRole::Free) == c.free);
    CHECK(sel.count(SelRole::Handle) == c.handle);
    CHECK(static_cast<Index>(sel.vertices(SelRole::Handle).size()) == c.handle);
    const Eigen::Matrix4d M = read_def(data + "/" + c.stem + ".def");
    // Every shared .def is a rigid motion: orthonormal with det +1 (to the
    // 6 printed digits).
    const Eigen::Matrix3d R = M.topLeftCorner<3, 3>();
    CHECK((R.transpose() * R - Eigen::Matrix3d::Identity()).norm() < 1e-5);
    CHECK(R.determinant() == Approx(1.0).margin(1e-5));
  }
  const Selection cyl = read_sel(data + "/meshes/botsch-sorkine/cylinder.sel");
  CHECK_THROWS_WITH(cyl.validate(5261), Catch::Contains("cylinder.sel: expected 5261 entries (one per mesh vertex), got 4802"));

  // The Laplacian-editing results put the handles at M·p (README: within 5e-6).
  const TriangleMesh rest = read_off(data + "/meshes/botsch-sorkine/cylinder.off");
  const TriangleMesh edited = read_off(data + "/meshes/botsch-sorkine/cylinder-laplacian_editing.off");
  const Eigen::Matrix4d M = read_def(data + "/meshes/botsch-sorkine/cylinder.def");
  double worst = 0.0;
  for (int v : cyl.vertices(SelRole::Handle)) {
    const Eigen::Vector3d p = M.topLeftCorner<3, 3>() * rest.V.row(v).transpose() + M.topRightCorner<3, 1>();
    worst = std::max(worst, (p - edited.V.row(v).transpose()).norm());
  }
  CHECK(worst < 1e-5);
}

TEST_CASE("paper-example .id files load, fit their meshes and give the README's groups", "[io][data][handles]") {
  REQUIRE_SHARED_DATA(data);
  enum Kind { Linear, Rotational, Affine };
  struct Case {
    const char* path;
    Index n;
    Kind kind;
    Index groups;       // linear groups / clusters (incl. painted ones) / patches
    Index painted;      // rotational: clusters from negative ids
    Index free;         // affine: vertices in no patch
  };
  // Group counts: the distinct ids of each file (checked with awk).
  const Case cases[] = {
      {"paper-examples/bar/bar_cluster27.id", 6084, Linear, 27, 0, 0},
      {"paper-examples/bar/bar_rotation.id", 6084, Rotational, 27, 2, 0},
      {"paper-examples/bar/bar_affine.id", 6084, Affine, 2, 0, -1},
      {"paper-examples/cactus/cactus_cluster27.id", 5261, Linear, 27, 0, 0},
      {"paper-examples/cactus/cactus_rotation25.id", 5261, Rotational, 27, 2, 0},
      {"paper-examples/cactus/cactus_affine.id", 5261, Affine, 2, 0, -1},
      {"paper-examples/cylinder/cylinder_cluster27.id", 4802, Linear, 27, 0, 0},
      {"paper-examples/cylinder/cylinder_rotation25.id", 4802, Rotational, 27, 2, 0},
      {"paper-examples/cylinder/cylinder_affine.id", 4802, Affine, 2, 0, -1},
      {"paper-examples/plane/plane_linear25_cluster.id", 40401, Linear, 27, 0, 0},
      {"paper-examples/plane/plane_rot25_cluster.id", 40401, Rotational, 27, 2, 0},
      {"paper-examples/plane/plane_affine.id", 40401, Affine, 2, 0, -1},
      {"paper-examples/dinosaur/dinosaur_lin34.id", 21074, Linear, 34, 0, 0},
      {"paper-examples/dinosaur/dinosaur_cluster30.id", 21074, Rotational, 34, 4, 0},
      {"paper-examples/dinosaur/dinosaur_affine.id", 21074, Affine, 4, 0, -1},
      {"paper-examples/dragon/dragon_cluster30.id", 52718, Rotational, 20, 0, 0},
      {"paper-examples/tree/tree_c60.id", 3630, Rotational, 60, 0, 0},
      {"paper-examples/teapot/cluster28.id", 10702, Linear, 28, 0, 0},
      {"paper-examples/teapot/rotation25.id", 10702, Rotational, 28, 3, 0},
      {"paper-examples/teapot/affine.id", 10702, Affine, 3, 0, -1},
  };
  for (const Case& c : cases) {
    INFO(c.path);
    const VertexIds ids = read_id(data + "/" + c.path);
    CHECK_NOTHROW(ids.validate(c.n));
    const VertexGroups g = c.kind == Linear       ? linear_groups_from_ids(ids)
                           : c.kind == Rotational ? rotation_groups_from_ids(ids)
                                                  : affine_patches_from_ids(ids);
    CHECK(g.size() == c.groups);
    Index members = 0, painted = 0;
    for (Index k = 0; k < g.size(); ++k) {
      CHECK_FALSE(g.members[k].empty());
      members += static_cast<Index>(g.members[k].size());
      painted += g.label[k] < 0 ? 1 : 0;
    }
    CHECK(painted == c.painted);
    const Index unassigned = static_cast<Index>(std::count(g.group_of.begin(), g.group_of.end(), -1));
    CHECK(members + unassigned == c.n);
    if (c.kind != Affine) CHECK(unassigned == 0);
    if (c.kind == Affine) CHECK(unassigned > 0);
  }
  const VertexIds rot = read_id(data + "/paper-examples/cylinder/cylinder_rotation25.id");
  CHECK_THROWS_WITH(linear_groups_from_ids(rot), Catch::Contains("cylinder_rotation25.id: vertex 0 has id -1; linear-group ids must be >= 0"));
  CHECK_THROWS_WITH(rot.validate(4801), Catch::Contains("expected 4801 entries (one per mesh vertex), got 4802"));
}

TEST_CASE("paper-example .anim files load and fit their meshes", "[io][data][handles]") {
  REQUIRE_SHARED_DATA(data);
  struct Case {
    const char* path;
    const char* mesh;
    Index handles;
  };
  const Case cases[] = {
      {"paper-examples/bar/rotated_hansel.anim", "meshes/botsch-sorkine/bar.off", 8},
      {"paper-examples/cactus/moved_hansel.anim", "meshes/botsch-sorkine/cactus.off", 9},
      {"paper-examples/cactus/origin_hansel.anim", "meshes/botsch-sorkine/cactus.off", 8},
      {"paper-examples/cactus/rotated_hansel.anim", "meshes/botsch-sorkine/cactus.off", 8},
      {"paper-examples/cylinder/newbend_hansel.anim", "meshes/botsch-sorkine/cylinder.off", 8},
      {"paper-examples/cylinder/rotated_hansel.anim", "meshes/botsch-sorkine/cylinder.off", 8},
      {"paper-examples/teapot/strench_hansel.anim", "paper-examples/teapot/teapot.off", 9},
      {"paper-examples/test2/arap_hansel.anim", "meshes/botsch-sorkine/cactus.off", 8},
  };
  for (const Case& c : cases) {
    INFO(c.path);
    const HandleAnimation a = read_anim(data + "/" + c.path);
    const TriangleMesh m = read_off(data + "/" + c.mesh);
    CHECK_NOTHROW(a.validate(m.V.rows()));
    CHECK(a.frames == 1);
    CHECK(a.handles() == c.handles);
    REQUIRE(a.targets.size() == 1);
    CHECK(a.targets[0].rows() == c.handles);
    CHECK(a.targets[0].allFinite());
    const std::vector<int> hv = a.handle_vertices();
    CHECK(std::set<int>(hv.begin(), hv.end()).size() == hv.size());
    CHECK(a.projection.empty());
    // The "origin" pose pins every handle at its rest position (to the 6
    // printed digits).
    if (std::string(c.path).find("origin") != std::string::npos) {
      for (std::size_t h = 0; h < hv.size(); ++h)
        CHECK((a.targets[0].row(static_cast<Index>(h)) - m.V.row(hv[h])).norm() < 1e-5);
    }
  }
}
