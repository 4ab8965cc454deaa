// Triangle mesh IO and the round trips of every mesh writer/reader pair
// (tets included): exact round trips, the OBJ, OFF and PLY variants the
// readers accept, and the error messages for malformed files.
#include "io_test_util.h"

#include "qpreduce/deform/io/mesh_io.h"
#include "qpreduce/deform/io/tet_io.h"

#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>

using namespace qpreduce::deform;
using Catch::Contains;
using io_test::TempDir;

namespace {

// Bit-exact equality, so that −0.0 and denormals count too.
bool same_bits(const Vertices& a, const Vertices& b) {
  return a.rows() == b.rows() && std::memcmp(a.data(), b.data(), sizeof(double) * a.size()) == 0;
}

std::string le_bytes(const void* p, std::size_t n) {
  // The test machine is little-endian (x86-64); the reader does not assume it.
  return std::string(static_cast<const char*>(p), n);
}
template <typename T>
std::string le(T v) {
  return le_bytes(&v, sizeof v);
}

}  // namespace

TEST_CASE("every triangle writer round-trips exactly through its reader", "[io][roundtrip]") {
  const TempDir dir;
  const TriangleMesh m = io_test::awkward_octahedron();
  struct Case {
    const char* name;
    void (*write)(const std::string&, const TriangleMesh&);
    const char* format;
  };
  const Case cases[] = {
      {"m.obj", [](const std::string& p, const TriangleMesh& x) { write_obj(p, x); }, "obj"},
      {"m.off", [](const std::string& p, const TriangleMesh& x) { write_off(p, x); }, "off"},
      {"m.ply", [](const std::string& p, const TriangleMesh& x) { write_ply(p, x); }, "ply-ascii"},
      {"b.ply", [](const std::string& p, const TriangleMesh& x) { write_ply(p, x, PlyEncoding::BinaryLittleEndian); },
       "ply-binary-le"},
      {"d.OBJ", [](const std::string& p, const TriangleMesh& x) { write_triangle_mesh(p, x); }, "obj"},
  };
  for (const Case& c : cases) {
    INFO(c.name);
    const std::string path = dir.path(c.name);
    c.write(path, m);
    MeshReadInfo info;
    const TriangleMesh r = read_triangle_mesh(path, &info);
    CHECK(info.format == c.format);
    CHECK(info.polygons_triangulated == 0);
    CHECK(info.unreferenced_vertices == 0);
    CHECK(same_bits(r.V, m.V));
    CHECK(r.F == m.F);
  }
}

TEST_CASE("every tet writer round-trips exactly through its reader", "[io][roundtrip]") {
  const TempDir dir;
  TetMesh with_faces = io_test::two_tets();
  TetMesh without_faces = with_faces;
  without_faces.F.resize(0, 3);
  for (const TetMesh* m : {&with_faces, &without_faces}) {
    const std::string tag = m->F.rows() > 0 ? "f" : "nof";
    for (const std::string& name : {tag + ".mesh", tag + ".node"}) {
      INFO(name);
      write_tet_mesh(dir.path(name), *m);
      MeshReadInfo info;
      const TetMesh r = read_tet_mesh(dir.path(name), &info);
      CHECK(same_bits(r.V, m->V));
      CHECK(r.T == m->T);
      CHECK(r.F == m->F);
      CHECK(info.unreferenced_vertices == 0);
    }
  }
  // The TetGen reader also takes the .ele path or the bare prefix.
  CHECK(read_tetgen(dir.path("f.ele")).T == with_faces.T);
  CHECK(read_tetgen(dir.path("f")).F == with_faces.F);
}

TEST_CASE("writers reject invalid meshes before touching the file", "[io][errors]") {
  const TempDir dir;
  TriangleMesh m = io_test::awkward_octahedron();
  m.V(2, 1) = std::numeric_limits<double>::quiet_NaN();
  CHECK_THROWS_AS(write_off(dir.path("nan.off"), m), std::invalid_argument);
  m = io_test::awkward_octahedron();
  m.F(3, 2) = 6;
  CHECK_THROWS_WITH(write_obj(dir.path("range.obj"), m), Contains("expected [0, 6), got [0, 6]"));
  CHECK_FALSE(io_test::fs::exists(dir.path("range.obj")));
  TetMesh t = io_test::two_tets();
  t.T.resize(0, 4);
  CHECK_THROWS_WITH(write_medit(dir.path("empty.mesh"), t), Contains("no tetrahedra"));
  CHECK_THROWS_WITH(write_triangle_mesh(dir.path("x.stl"), io_test::awkward_octahedron()),
                    Contains("unsupported triangle mesh extension '.stl'"));
  CHECK_THROWS_AS(write_off(dir.path("no/such/dir/x.off"), io_test::awkward_octahedron()), IoError);
}

TEST_CASE("OBJ variants: corner forms, relative indices, comments, polygons", "[io][obj]") {
  const TempDir dir;
  const std::string path = dir.write("v.obj",
                                     "# a comment line\n"
                                     "mtllib x.mtl\n"
                                     "o thing\n"
                                     "v 0 0 0\n"
                                     "v 1 0 0 1.0\n"          // w ignored
                                     "v 1 1 0 0.5 0.5 0.5\n"  // a color ignored
                                     "v 0 1 0   # trailing comment\n"
                                     "vt 0.5 0.5\n"
                                     "vn 0 0 1\n"
                                     "g group\n"
                                     "s off\n"
                                     "usemtl m\n"
                                     "f 1/1/1 2/1/1 3/1/1\n"
                                     "f 1//1 3//1 4//1\n"
                                     "f 1/1 2/1 3/1\n"
                                     "f -4 -3 -1\n"
                                     "f 1 2 3 4\n"  // a quad: two triangles
                                     "l 1 2\n"
                                     "\n"
                                     "v 0.5 0.5 1\n"
                                     "f 1 2 5\n");
  MeshReadInfo info;
  const TriangleMesh m = read_obj(path, &info);
  REQUIRE(m.V.rows() == 5);
  REQUIRE(m.F.rows() == 7);
  CHECK(m.V.row(1) == Eigen::RowVector3d(1, 0, 0));
  CHECK(m.V.row(2) == Eigen::RowVector3d(1, 1, 0));
  CHECK(m.F.row(1) == Eigen::RowVector3i(0, 2, 3));
  CHECK(m.F.row(3) == Eigen::RowVector3i(0, 1, 3));  // -4 -3 -1 with 4 vertices read
  CHECK(m.F.row(4) == Eigen::RowVector3i(0, 1, 2));  // fan of the quad
  CHECK(m.F.row(5) == Eigen::RowVector3i(0, 2, 3));
  CHECK(info.polygons_triangulated == 1);
  CHECK(info.notes.size() == 2);  // the quad, the 'l' line
}

TEST_CASE("OBJ errors name the file, the line and the problem", "[io][obj][errors]") {
  const TempDir dir;
  const std::string v3 = "v 0 0 0\nv 1 0 0\nv 0 1 0\n";
  CHECK_THROWS_WITH(read_obj(dir.path("none.obj")), Contains("none.obj: cannot open file"));
  io_test::check_malformed(dir, [](const std::string& p) { return read_obj(p); }, {
      {"zero.obj", v3 + "f 0 1 2\n",
       "zero.obj:4: vertex index 0"},
      {"range.obj", v3 + "f 1 2 4\n",
       "range.obj:4: vertex index 4 out of range (the file has 3 vertices"},
      {"rel.obj", v3 + "f -1 -2 -4\n",
       "relative vertex index -4 refers before the first vertex"},
      {"two.obj", v3 + "f 1 2\n",
       "two.obj:4: face with 2 corner(s)"},
      {"nan.obj", "v 0 0 0\nv 1 nan 0\n",
       "nan.obj:2: non-finite value 'nan' (y coordinate)"},
      {"inf.obj", "v 0 0 -inf\n",
       "non-finite value '-inf'"},
      {"short.obj", "v 0 0\n",
       "short.obj:1: missing z coordinate"},
      {"bad.obj", "v 0 0 1.5e\n",
       "bad.obj:1: malformed number '1.5e' (expected z coordinate)"},
      {"badidx.obj", v3 + "f 1 2.0 3\n",
       "malformed integer '2.0'"},
      {"slash.obj", v3 + "f /1 2 3\n",
       "has no vertex index"},
      {"nofaces.obj", v3,
       "nofaces.obj: no faces (degenerate input)"},
      {"empty.obj", "",
       "no vertices"},
  });
}

TEST_CASE("OFF variants: COFF, comments, counts on the keyword line, edges, colors, polygons", "[io][off]") {
  const TempDir dir;
  const TriangleMesh a = read_off(dir.write("c.off",
                                            "COFF\n"
                                            "# comment before the counts\n"
                                            "4 2 5\n"
                                            "0 0 0 255 0 0 255\n"
                                            "1 0 0 0 255 0 255\n"
                                            "1 1 0 0 0 255 255  # comment\n"
                                            "\n"
                                            "0 1 0 1 1 1 1\n"
                                            "3 0 1 2 0.5 0.5 0.5\n"
                                            "3 0 2 3\n"));
  CHECK(a.V.rows() == 4);
  CHECK(a.F == (Triangles(2, 3) << 0, 1, 2, 0, 2, 3).finished());
  MeshReadInfo info;
  const TriangleMesh b = read_off(dir.write("q.off", "OFF 5 2 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n0 0 1\n"
                                                     "4 0 1 2 3\n3 0 1 4\n"),
                                  &info);
  CHECK(b.F.rows() == 3);
  CHECK(info.polygons_triangulated == 1);
  CHECK(read_off(dir.write("n.off", "NOFF\n3 1 0\n0 0 0 0 0 1\n1 0 0 0 0 1\n0 1 0 0 0 1\n3 0 1 2\n")).V.rows() == 3);
}

TEST_CASE("OFF errors name the file, the line and the problem", "[io][off][errors]") {
  const TempDir dir;
  const std::string head = "OFF\n4 2 0\n0 0 0\n1 0 0\n1 1 0\n";
  io_test::check_malformed(dir, [](const std::string& p) { return read_off(p); }, {
      {"trunc.off", head,
       "trunc.off:5: unexpected end of file after 3 of 4 vertices"},
      {"truncf.off", head + "0 1 0\n3 0 1 2\n",
       "unexpected end of file after 1 of 2 faces"},
      {"nan.off", "OFF\n3 1 0\n0 0 0\n1 NaN 0\n0 1 0\n3 0 1 2\n",
       "nan.off:4: non-finite value 'NaN' (y coordinate)"},
      {"range.off", head + "0 1 0\n3 0 1 2\n3 0 2 7\n",
       "range.off:8: vertex index 7 out of range (the file has 4 vertices, indices start at 0)"},
      {"neg.off", head + "0 1 0\n3 0 1 2\n3 0 -2 3\n",
       "vertex index -2 out of range"},
      {"more.off", head + "0 1 0\n3 0 1 2\n3 0 2 3\n3 0 1 3\n",
       "more.off:9: unexpected data after the 2 faces the header announced"},
      {"zero.off", "OFF\n3 0 0\n0 0 0\n1 0 0\n0 1 0\n",
       "zero.off: no faces (degenerate input)"},
      {"garbage.off", "PLY\n3 1 0\n",
       "garbage.off:1: not an OFF file (first token 'PLY'"},
      {"4d.off", "4OFF\n1 0 0\n",
       "only 3-dimensional OFF"},
      {"bin.off", "OFF BINARY\n",
       "binary OFF is not supported"},
      {"badnum.off", "OFF\n3 1 0\n0 0 0\n1 0.5.1 0\n0 1 0\n3 0 1 2\n",
       "badnum.off:4: malformed number '0.5.1'"},
      {"line.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n2 0 1\n",
       "line.off:6: face with 2 corner(s)"},
      {"negcount.off", "OFF\n-3 1 0\n",
       "negative count"},
      {"empty.off", "",
       "empty file"},
  });
  CHECK_THROWS_WITH(read_triangle_mesh(dir.write("x.stl", "solid")),
                    Contains("unsupported triangle mesh extension '.stl'"));
}

TEST_CASE("PLY variants: other types, properties, elements and list types", "[io][ply]") {
  const TempDir dir;
  // ASCII: float coordinates among other properties, an extra element,
  // `vertex_index` with ushort count and uint indices, a quad.
  const std::string ascii =
      "ply\nformat ascii 1.0\ncomment made by hand\nobj_info nothing\n"
      "element vertex 4\nproperty uchar red\nproperty float x\nproperty float y\nproperty float z\n"
      "property list uchar float extra\n"
      "element face 1\nproperty list ushort uint vertex_index\nproperty int flags\n"
      "element edge 1\nproperty int vertex1\nproperty int vertex2\n"
      "end_header\n"
      "255 0 0 0 2 0.5 0.25\n10 1 0 0 0\n10 1 1 0 1 7\n10 0 1 0.5 0\n"
      "4 0 1 2 3 99\n"
      "0 1\n";
  MeshReadInfo info;
  const TriangleMesh a = read_ply(dir.write("a.ply", ascii), &info);
  CHECK(info.format == "ply-ascii");
  CHECK(a.V.row(3) == Eigen::RowVector3d(0, 1, 0.5));
  CHECK(a.F.rows() == 2);
  CHECK(info.polygons_triangulated == 1);

  // Binary little-endian: int16 x, float y, double z, a char property, a
  // face list with an int count and short indices, written byte by byte.
  std::string bin =
      "ply\r\nformat binary_little_endian 1.0\r\nelement vertex 3\r\nproperty short x\r\nproperty char c\r\n"
      "property float y\r\nproperty double z\r\nelement face 1\r\nproperty int n\r\n"
      "property list int short vertex_indices\r\nend_header\r\n";
  const double z = 1.0 / 3.0;
  for (int i = 0; i < 3; ++i)
    bin += le<std::int16_t>(static_cast<std::int16_t>(-i)) + le<std::int8_t>(-1) + le<float>(0.5f * i) + le<double>(z * i);
  bin += le<std::int32_t>(42) + le<std::int32_t>(3) + le<std::int16_t>(2) + le<std::int16_t>(1) + le<std::int16_t>(0);
  const TriangleMesh b = read_ply(dir.write("b.ply", bin), &info);
  CHECK(info.format == "ply-binary-le");
  CHECK(b.V.row(2) == Eigen::RowVector3d(-2, 1.0, 2 * z));
  CHECK(b.F.row(0) == Eigen::RowVector3i(2, 1, 0));
}

TEST_CASE("PLY errors name the file, the line and the problem", "[io][ply][errors]") {
  const TempDir dir;
  const std::string header =
      "ply\nformat ascii 1.0\nelement vertex 3\nproperty double x\nproperty double y\nproperty double z\n"
      "element face 1\nproperty list uchar int vertex_indices\nend_header\n";
  std::string be = header;
  be.replace(be.find("ascii"), 5, "binary_big_endian");
  std::string noy = header;
  noy.replace(noy.find("property double y\n"), 18, "");
  const std::string noface = header.substr(0, header.find("element face")) + "end_header\n0 0 0\n1 0 0\n0 1 0\n";
  std::string zero = header;
  zero.replace(zero.find("face 1"), 6, "face 0");
  io_test::check_malformed(dir, [](const std::string& p) { return read_ply(p); }, {
      {"trunc.ply", header + "0 0 0\n1 0 0\n",
       "trunc.ply:11: unexpected end of file in element 'vertex' (2 of 3"},
      {"nan.ply", header + "0 0 0\n1 0 nan\n0 1 0\n3 0 1 2\n",
       "nan.ply:11: non-finite value 'nan'"},
      {"range.ply", header + "0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n",
       "range.ply:13: vertex index 3 out of range (the file has 3 vertices"},
      {"extra.ply", header + "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n3 0 1 2\n",
       "extra.ply:14: unexpected data after the last element"},
      {"be.ply", be,
       "be.ply:2: binary_big_endian PLY is not supported (only ascii and binary_little_endian)"},
      {"garbage.ply", "plz\nformat ascii 1.0\n",
       "garbage.ply:1: not a PLY file"},
      {"noend.ply", "ply\nformat ascii 1.0\nelement vertex 0\n",
       "no end_header line"},
      {"type.ply", "ply\nformat ascii 1.0\nelement vertex 1\nproperty real x\n",
       "type.ply:4: unknown PLY property type 'real'"},
      {"hdr.ply", "ply\nformat ascii 1.0\nelemnt vertex 1\n",
       "hdr.ply:3: unexpected PLY header line starting with 'elemnt'"},
      {"noy.ply", noy,
       "no scalar property 'y'"},
      {"noface.ply", noface,
       "no 'face' element"},
      {"zero.ply", zero + "0 0 0\n1 0 0\n0 1 0\n",
       "no faces"},
  });

  // Binary: cut in the middle of the faces.
  TriangleMesh m = io_test::awkward_octahedron();
  write_ply(dir.path("full.ply"), m, PlyEncoding::BinaryLittleEndian);
  std::string bytes;
  {
    std::ifstream in(dir.path("full.ply"), std::ios::binary);
    bytes.assign(std::istreambuf_iterator<char>(in), {});
  }
  CHECK_THROWS_WITH(read_ply(dir.write("cut.ply", bytes.substr(0, bytes.size() - 20))),
                    Contains("cut.ply: unexpected end of file in element 'face' (6 of 8)"));
  CHECK_THROWS_WITH(read_ply(dir.write("tail.ply", bytes + "xyz")), Contains("3 unexpected byte(s) after the last element"));
  std::string nan_bytes = bytes;
  const double nan = std::numeric_limits<double>::quiet_NaN();
  nan_bytes.replace(nan_bytes.find("end_header\n") + 11 + 8, 8, le<double>(nan));
  CHECK_THROWS_WITH(read_ply(dir.write("bnan.ply", nan_bytes)), Contains("non-finite value"));
}
