// Tet mesh readers: the MEDIT and TetGen variants they accept and the error
// messages for malformed files (round trips are in mesh_io_test.cpp); the
// TetGen writer's files written all together.
#include "io_test_util.h"

#include "qpreduce/deform/io/tet_io.h"
#include "qpreduce/deform/mesh/shapes.h"

#include <filesystem>
#include <fstream>
#include <iterator>

using namespace qpreduce::deform;
using Catch::Contains;
using io_test::TempDir;
namespace fs = std::filesystem;

TEST_CASE("MEDIT variants and errors", "[io][medit]") {
  const TempDir dir;
  const std::string vertices = "Vertices\n4\n0 0 0 1\n1 0 0 1\n0 1 0 1\n0 0 1 1\n";
  const std::string good = "MeshVersionFormatted 2\n# comment\nDimension\n3\n" + vertices +
                           "Corners\n2\n1\n2\nEdges\n1\n1 2 0\nTetrahedra\n1\n1 2 3 4 7\nEnd\n";
  MeshReadInfo info;
  const TetMesh m = read_medit(dir.write("good.mesh", good), &info);
  CHECK(m.T.row(0) == Eigen::RowVector4i(0, 1, 2, 3));
  CHECK(m.F.rows() == 0);
  CHECK(info.notes.size() == 2);  // skipped Corners and Edges

  io_test::check_malformed(dir, [](const std::string& p) { return read_medit(p); }, {
      {"dim.mesh", "Dimension 2\n",
       "dim.mesh:1: Dimension 2: only 3-dimensional meshes are supported"},
      {"unk.mesh", vertices + "Bananas\n3\n",
       "unk.mesh:7: unknown MEDIT section 'Bananas'"},
      {"trunc.mesh", "Vertices\n4\n0 0 0 1\n1 0 0 1\n",
       "trunc.mesh:4: unexpected end of file after 2 of 4 vertices"},
      {"zero.mesh", vertices + "Tetrahedra\n1\n0 1 2 3 0\n",
       "zero.mesh:9: vertex index 0 (MEDIT indices start at 1)"},
      {"range.mesh", vertices + "Tetrahedra\n1\n1 2 3 5 0\n",
       "range.mesh:9: vertex index 5 out of range (the file has 4 vertices, indices start at 1)"},
      {"notet.mesh", vertices + "Triangles\n1\n1 2 3 0\nEnd\n",
       "no Tetrahedra section"},
      {"nan.mesh", "Vertices\n1\n0 inf 0 1\n",
       "non-finite value 'inf'"},
  });
  CHECK_THROWS_WITH(read_tet_mesh(dir.write("x.meshb", "")), Contains("unsupported tet mesh extension '.meshb'"));
}

TEST_CASE("TetGen variants and errors", "[io][tetgen]") {
  const TempDir dir;
  // 1-based, with attributes and markers, comments.
  dir.write("one.node", "# nodes\n4 3 1 1\n1 0 0 0 9.5 1\n2 1 0 0 9.5 1\n3 0 1 0 9.5 1\n4 0 0 1 9.5 0\n");
  dir.write("one.ele", "1 4 1\n1 1 2 3 4 2.0  # tet\n");
  dir.write("one.face", "1 1\n1 1 3 2 -1\n");
  MeshReadInfo info;
  const TetMesh m = read_tet_mesh(dir.path("one.node"), &info);
  CHECK(info.format == "tetgen");
  CHECK(m.T.row(0) == Eigen::RowVector4i(0, 1, 2, 3));
  CHECK(m.F.row(0) == Eigen::RowVector3i(0, 2, 1));

  const std::string node = "4 3 0 0\n0 0 0 0\n1 1 0 0\n2 0 1 0\n3 0 0 1\n";
  dir.write("a.node", "4 3 0 0\n0 0 0 0\n1 1 0 0\n2 0 1 0\n");
  dir.write("a.ele", "1 4 0\n0 0 1 2 3\n");
  CHECK_THROWS_WITH(read_tetgen(dir.path("a.node")), Contains("a.node:4: unexpected end of file after 3 of 4 nodes"));
  dir.write("b.node", node);
  dir.write("b.ele", "1 4 0\n0 0 1 2 4\n");
  CHECK_THROWS_WITH(read_tetgen(dir.path("b.ele")),
                    Contains("b.ele:2: vertex index 4 out of range (the file has 4 vertices, indices start at 0)"));
  dir.write("c.node", "4 3 0 0\n0 0 0 0\n1 1 0 0\n2 0 1 0 7\n3 0 0 1\n");
  CHECK_THROWS_WITH(read_tetgen(dir.path("c.node")), Contains("c.node:4: expected 4 columns, got 5"));
  dir.write("d.node", "4 3 0 0\n0 0 0 0\n1 1 0 0\n3 0 1 0\n4 0 0 1\n");
  CHECK_THROWS_WITH(read_tetgen(dir.path("d.node")), Contains("d.node:4: id 3 out of sequence (expected 2)"));
  dir.write("e.node", node);
  CHECK_THROWS_WITH(read_tetgen(dir.path("e.node")), Contains("e.ele: cannot open file"));
  dir.write("f.node", "4 2 0 0\n");
  CHECK_THROWS_WITH(read_tetgen(dir.path("f.node")), Contains("only 3-dimensional"));
  dir.write("g.node", node);
  dir.write("g.ele", "0 4 0\n");
  CHECK_THROWS_WITH(read_tetgen(dir.path("g.node")), Contains("g.ele: no tetrahedra (degenerate input)"));
  dir.write("h.node", "4 3 0 0\n0 0 0 0\n1 1 0 0\n2 0 nan 0\n3 0 0 1\n");
  CHECK_THROWS_WITH(read_tetgen(dir.path("h.node")), Contains("h.node:4: non-finite value 'nan'"));
  dir.write("i.node", node + "4 1 1 1\n");
  CHECK_THROWS_WITH(read_tetgen(dir.path("i.node")), Contains("unexpected data after the 4 nodes"));
  dir.write("j.node", node);
  dir.write("j.ele", "1 4 0\n0 0 1 2 3\n");
  dir.write("j.face", "2 0\n0 0 1 2\n");
  CHECK_THROWS_WITH(read_tetgen(dir.path("j.node")), Contains("j.face:2: unexpected end of file after 1 of 2 faces"));
}

TEST_CASE("TetGen writer: the .node, .ele and .face files together or none", "[io][tetgen][writers]") {
  const TempDir dir;
  const TetMesh earlier = shapes::box_tets(1, 1, 1, 1, 1, 1);
  write_tetgen(dir.path("m.node"), earlier);
  auto read = [&](const std::string& name) {
    std::ifstream in(dir.path(name), std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(in), {});
  };
  const std::string node = read("m.node"), face = read("m.face");
  REQUIRE(!node.empty());
  REQUIRE(!face.empty());
  // The .ele is a link to a full device (written in place, fails): the .node
  // and .face written before or after it must not be replaced.
  if (!fs::exists("/dev/full")) return;
  fs::remove(dir.path("m.ele"));
  fs::create_symlink("/dev/full", dir.path("m.ele"));
  CHECK_THROWS_WITH(write_tetgen(dir.path("m.node"), shapes::box_tets(2, 2, 2, 3, 3, 3)),
                    Contains("m.ele") && Contains("No space left on device"));
  CHECK(read("m.node") == node);
  CHECK(read("m.face") == face);
  int entries = 0;
  for (const auto& e : fs::directory_iterator(dir.path(""))) entries += e.path().filename().string()[0] != '.' ? 1 : 100;
  CHECK(entries == 3);  // m.node, m.ele, m.face; no temporary (".m.node.tmp…")
}
