// The JSON scene: every field, its errors (naming the scene and the JSON
// pointer), and the scenarios built from it.
#include "io_test_util.h"

#include "qpreduce/deform/io/handles_io.h"
#include "qpreduce/deform/io/mesh_io.h"
#include "qpreduce/deform/io/scenario.h"
#include "qpreduce/deform/io/scene.h"
#include "qpreduce/deform/io/tet_io.h"
#include "qpreduce/deform/mesh/shapes.h"

#include <algorithm>
#include <limits>
#include <utility>

using namespace qpreduce::deform;
using Catch::Contains;
using io_test::TempDir;
using qpreduce::Index;

namespace {
// A scene next to a written octahedron (6 vertices) and its .sel/.id files.
struct SceneDir {
  TempDir dir;
  SceneDir() {
    write_off(dir.path("octa.off"), io_test::awkward_octahedron());
    dir.write("octa.sel", "# 6 vertices\n0\n1\n2\n1\n2\n0\n");
    dir.write("octa.def", "# m\n1 0 0 1\n0 1 0 2\n0 0 1 3\n0 0 0 1\n");
    dir.write("lin.id", "0\n0\n1\n1\n2\n2\n");
    dir.write("rot.id", "0\n0\n0\n-1\n1\n1\n");
    dir.write("aff.id", "0\n1\n1\n0\n0\n0\n");
    dir.write("h.anim", "1 1 6 1 0 0 0\n0 0 0 0 1 0\n9 9 9\n");
  }
  std::string scene(const std::string& json) const { return dir.write("scene.json", json); }
};
}  // namespace

TEST_CASE("JSON scene: every field, resolved and checked against the mesh", "[io][scene]") {
  const SceneDir s;
  const Scene sc = read_scene(s.scene(R"({
    "description": "everything at once",
    "mesh": "octa.off",
    "energy": {"alpha": 1.0, "beta": 0.5, "gamma": 0, "model": "conformal", "psi": 1.5},
    "solver": {"iterations": 4, "constraints": "soft", "delta": 1e-3},
    "proxies": {"linear": "lin.id", "rotational": "rot.id", "affine": "aff.id"},
    "patches": [
      {"type": "fixed", "sel": {"file": "octa.sel", "role": "fixed"}},
      {"type": "rigid", "vertices": [3, 1]},
      {"type": "affine", "id": {"file": "aff.id", "value": 1}}
    ],
    "handles": [
      {"name": "cap", "sel": {"file": "octa.sel", "role": 2}, "def": "octa.def"},
      {"name": "pts", "vertices": [1, 3], "targets": [[[0, 0, 0], [1, 1, 1]], [[0, 0, 1], [1, 1, 2]]]},
      {"name": "grip", "group": [[0, 0.25], [5, 0.75]], "targets": [[1, 2, 3]]},
      {"name": "spin", "vertices": [0], "transforms": [
          [1, 0, 0, 0,  0, 1, 0, 0,  0, 0, 1, 0,  0, 0, 0, 1],
          [[0, -1, 0, 0], [1, 0, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]]},
      {"anim": "h.anim", "name": "demo"}
    ]
  })"));
  CHECK_FALSE(sc.is_tet);
  CHECK(sc.vertex_count() == 6);
  CHECK(*sc.alpha == 1.0);
  CHECK(*sc.beta == 0.5);
  CHECK(*sc.gamma == 0.0);
  CHECK(*sc.model == "conformal");
  CHECK(*sc.psi == 1.5);
  CHECK(*sc.iterations == 4);
  CHECK(sc.constraints == ConstraintMode::Soft);
  CHECK(*sc.delta == 1e-3);
  CHECK(sc.linear_proxies.count == 3);
  CHECK(sc.rotational_clusters.groups.label == std::vector<int>{0, 1, -1});
  CHECK(sc.affine_patches.groups.members == std::vector<std::vector<int>>{{1, 2}});
  REQUIRE(sc.patches.size() == 3);
  CHECK(sc.patches[0].vertices == std::vector<int>{0, 5});
  CHECK(sc.patches[1].type == PatchType::Rigid);
  CHECK(sc.patches[1].vertices == std::vector<int>{1, 3});
  CHECK(sc.patches[2].vertices == std::vector<int>{1, 2});
  REQUIRE(sc.handles.size() == 5);
  CHECK(sc.frames == 2);
  const Vertices& V = sc.rest_positions();
  // .def: translation by (1, 2, 3) of the handle vertices 2 and 4, every frame.
  const Vertices cap = sc.handles[0].targets_at(1, V);
  CHECK(cap.row(1) == V.row(4) + Eigen::RowVector3d(1, 2, 3));
  CHECK(sc.handles[1].targets_at(1, V).row(1) == Eigen::RowVector3d(1, 1, 2));
  CHECK(sc.handles[2].is_group());
  CHECK(sc.handles[2].targets_at(1, V).row(0) == Eigen::RowVector3d(1, 2, 3));
  const Vertices spun = sc.handles[3].targets_at(1, V);
  CHECK(spun(0, 0) == -V(0, 1));
  CHECK(spun(0, 1) == V(0, 0));
  CHECK(sc.handles[4].name == "demo[0]");
  CHECK(sc.handles[4].vertices == std::vector<int>{4});
  CHECK(sc.handles[4].targets_at(0, V) == Eigen::RowVector3d(9, 9, 9));

  // The files it names, as read and as found from the JSON alone (the
  // check that no output is an input runs before the scene is read).
  const auto sorted = [](std::vector<SceneFile> files) {
    std::vector<std::pair<std::string, std::string>> out;
    for (const SceneFile& f : files) out.emplace_back(f.where, f.path);
    std::sort(out.begin(), out.end());
    return out;
  };
  const auto read = sorted(sc.files);
  CHECK(read.size() == 9);  // the mesh, three proxy files, two patch files, three handle files
  CHECK(read == sorted(scene_files(s.dir.path("scene.json"))));
  CHECK(std::find(read.begin(), read.end(), std::make_pair(std::string("/handles/0/def"), s.dir.path("octa.def"))) !=
        read.end());
}

TEST_CASE("JSON scene: scene_files refuses what is not JSON, and lists what a broken scene names", "[io][scene][errors]") {
  const SceneDir s;
  CHECK_THROWS_WITH(scene_files(s.scene("{\"mesh\": ")), Contains("scene.json") && Contains("syntax"));
  CHECK_THROWS_WITH(scene_files(s.dir.path("none.json")), Contains("none.json"));
  // Not a scene read_scene accepts (an unknown key), but the paths are named.
  const std::vector<SceneFile> files = scene_files(s.scene(R"({"mesh": "octa.off", "handels": [], "handles": [7]})"));
  REQUIRE(files.size() == 1);
  CHECK(files[0].where == "/mesh");
  CHECK(files[0].path == s.dir.path("octa.off"));
}

TEST_CASE("JSON scene errors name the scene and the JSON pointer", "[io][scene][errors]") {
  const SceneDir s;
  const auto fails_with = [&](const std::string& json, const std::string& message) {
    INFO(json);
    CHECK_THROWS_WITH(read_scene(s.scene(json)), Contains(message));
  };
  fails_with(R"({"mesh": "octa.off",)", "scene.json: JSON syntax error");
  fails_with(R"([1, 2])", "scene.json: the scene must be a JSON object");
  fails_with(R"({"mesh": "octa.off", "energy": {"alpha": 1e400}})", "scene.json: JSON value out of range");
  fails_with(R"({"handels": []})", "scene.json: unknown key 'handels'");
  fails_with(R"({"energy": {}})", "scene.json: /: missing key 'mesh'");
  fails_with(R"({"mesh": "nowhere.off"})", "nowhere.off: cannot open file");
  fails_with(R"({"mesh": "octa.off", "energy": {"alpha": "big"}})", "scene.json: /energy/alpha: expected a number");
  fails_with(R"({"mesh": "octa.off", "energy": {"beta": -1}})", "/energy/beta: must be >= 0");
  fails_with(R"({"mesh": "octa.off", "energy": {"model": "rigid"}})", "/energy/model: expected \"arap\" or \"conformal\"");
  fails_with(R"({"mesh": "octa.off", "energy": {"psi": 0.5}})", "/energy/psi: must be > 1");
  fails_with(R"({"mesh": "octa.off", "solver": {"constraints": "firm"}})", "/solver/constraints: expected \"hard\" or \"soft\"");
  fails_with(R"({"mesh": "octa.off", "solver": {"iterations": 2.5}})", "/solver/iterations: expected an integer");
  fails_with(R"({"mesh": "octa.off", "solver": {"delta": 0}})", "/solver/delta: must be > 0");
  fails_with(R"({"mesh": "octa.off", "proxies": {"linear": 0}})", "/proxies/linear: a proxy count must be >= 1");
  fails_with(R"({"mesh": "octa.off", "proxies": {"linear": "rot.id"}})", "rot.id: vertex 3 has id -1");
  fails_with(R"({"mesh": "octa.off", "patches": [{"type": "fixed", "vertices": [0, 6]}]})",
             "scene.json: /patches/0/vertices/1: vertex 6 out of range (the mesh has 6 vertices)");
  fails_with(R"({"mesh": "octa.off", "patches": [{"type": "bendy", "vertices": [0]}]})", "/patches/0/type: expected");
  fails_with(R"({"mesh": "octa.off", "patches": [{"type": "fixed", "vertices": [0, 0]}]})", "a vertex is listed twice");
  fails_with(R"({"mesh": "octa.off", "patches": [{"type": "fixed", "id": {"file": "lin.id", "value": 7}}]})",
             "/patches/0: selects no vertex");
  fails_with(R"({"mesh": "octa.off", "handles": [{"vertices": [0]}]})",
             "/handles/0: expected exactly one of 'targets', 'transforms', 'def'");
  fails_with(R"({"mesh": "octa.off", "handles": [{"vertices": [0, 1], "targets": [[[0, 0, 0]]]}]})",
             "/handles/0/targets/0: expected 2 points (one per handle vertex), got 1");
  fails_with(R"({"mesh": "octa.off", "handles": [{"group": [[0, 1]], "targets": [[0, 0]]}]})",
             "/handles/0/targets/0: expected 3 numbers, got 2");
  fails_with(R"({"mesh": "octa.off", "handles": [{"vertices": [0], "transforms": [[1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 1, 1]]}]})",
             "/handles/0/transforms/0: the last row of a transform must be 0 0 0 1");
  fails_with(R"({"mesh": "octa.off", "handles": [{"vertices": [0], "targets": []}]})", "/handles/0: no frames");
  fails_with(R"({"mesh": "octa.off", "handles": [
                  {"vertices": [0], "targets": [[[0, 0, 0]], [[0, 0, 0]]]},
                  {"vertices": [1], "targets": [[[0, 0, 0]], [[0, 0, 0]], [[0, 0, 0]]]}]})",
             "/handles/0: 2 frames, but another handle has 3");
  fails_with(R"({"mesh": "octa.off", "handles": [{"sel": {"file": "octa.sel", "role": "boss"}, "def": "octa.def"}]})",
             "/handles/0/sel/role: expected");
  s.dir.write("short.sel", "0\n1\n");
  fails_with(R"({"mesh": "octa.off", "handles": [{"sel": {"file": "short.sel", "role": 1}, "def": "octa.def"}]})",
             "short.sel: expected 6 entries (one per mesh vertex), got 2");
  s.dir.write("long.anim", "1 1 7 1 0 0 0\n0 0 0 0 1 0 0\n9 9 9\n");
  fails_with(R"({"mesh": "octa.off", "handles": [{"anim": "long.anim"}]})",
             "long.anim: expected 6 entries (one per mesh vertex), got 7");
}

TEST_CASE("JSON scene with a shared tet mesh and the Botsch-Sorkine files", "[io][scene][data]") {
  REQUIRE_SHARED_DATA(data);
  const TempDir dir;
  const std::string json = R"({
    "mesh": ")" + data + R"(/tets/solid_cylinder.node",
    "patches": [{"type": "fixed", "sel": {"file": ")" + data + R"(/meshes/botsch-sorkine/cylinder.sel", "role": "fixed"}}],
    "handles": [{"sel": {"file": ")" + data + R"(/meshes/botsch-sorkine/cylinder.sel", "role": "handle"},
                 "def": ")" + data + R"(/meshes/botsch-sorkine/cylinder.def"}]
  })";
  // The .sel has 4,802 entries, the solid 7,924 nodes: the scene rejects it.
  CHECK_THROWS_WITH(read_scene(dir.write("solid.json", json)),
                    Contains("cylinder.sel: expected 7924 entries (one per mesh vertex), got 4802"));
  std::string surface = json;
  surface.replace(surface.find("tets/solid_cylinder.node"), 24, "meshes/botsch-sorkine/cylinder.off");
  const Scene sc = read_scene(dir.write("surface.json", surface));
  CHECK(sc.patches[0].vertices.size() == 241);
  CHECK(sc.handles[0].points() == 241);
  CHECK(sc.frames == 1);
}

TEST_CASE("JSON scene: a transform handle on exactly a patch prescribes that patch", "[io][scene]") {
  const SceneDir s;
  const Scenario sc = scenario_from_scene(read_scene(s.scene(R"({
    "mesh": "octa.off",
    "patches": [{"type": "fixed", "vertices": [0]}, {"type": "rigid", "vertices": [3, 1]}],
    "handles": [
      {"name": "turn", "vertices": [1, 3], "transforms": [[[0, -1, 0, 0], [1, 0, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]]},
      {"name": "pin", "vertices": [5], "transforms": [[1, 0, 0, 0.5, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]]}
    ]
  })")));
  REQUIRE(sc.handles.patches.size() == 1);
  CHECK(sc.model.patch_types[static_cast<size_t>(sc.handles.patches[0])] == PatchType::Rigid);
  REQUIRE(sc.handles.points.size() == 1);  // vertex 5 is not a patch: a point handle
  CHECK(sc.handles.points[0].vertices == std::vector<Index>{5});
  REQUIRE(sc.frames.size() == 1);
  REQUIRE(sc.frames[0].patch_transforms.size() == 1);
  CHECK(sc.frames[0].patch_transforms[0](0, 1) == -1.0);
  CHECK(sc.frames[0].points(0, 0) == Approx(sc.model.V(5, 0) + 0.5));
}

TEST_CASE("anchored_vertices refuses handles and patch labels that do not fit the model", "[io][scene][errors]") {
  const TriangleMesh mesh = shapes::capped_cylinder(1.0, 4.0, 12, 6);
  Selection sel;
  for (Index v = 0; v < mesh.V.rows(); ++v)
    sel.roles.push_back(mesh.V(v, 2) < 0.3 ? SelRole::Fixed : mesh.V(v, 2) > 3.7 ? SelRole::Handle : SelRole::Free);
  Scenario sc = scenario_from_sel_def(mesh.V, sel, Eigen::Matrix4d::Identity(), 1);
  sc.model.F = mesh.F;
  CHECK(anchored_vertices(sc).size() == static_cast<size_t>(mesh.V.rows()));
  Scenario far = sc;
  far.handles.points.push_back({{1000000}, {}});
  CHECK_THROWS_WITH(anchored_vertices(far), Catch::Contains("vertex 1000000 outside [0, 74)"));
  Scenario labels = sc;
  labels.model.patch_of_vertex.assign(static_cast<size_t>(mesh.V.rows()), 4);
  CHECK_THROWS_WITH(anchored_vertices(labels), Catch::Contains("anchored_vertices: vertex 0 has patch 4 outside"));
}
