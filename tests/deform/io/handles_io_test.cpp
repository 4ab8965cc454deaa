// .sel/.def/.id/.anim parsing and errors on small files.
#include "io_test_util.h"

#include "qpreduce/deform/io/handles_io.h"

using namespace qpreduce::deform;
using Catch::Contains;
using io_test::TempDir;
using qpreduce::Index;

TEST_CASE(".sel: roles, declared count, errors", "[io][handles]") {
  const TempDir dir;
  const Selection s = read_sel(dir.write("a.sel", "# per vertex status\n# 5 vertices\n0\n1\n2\n2\n1\n"));
  CHECK(s.size() == 5);
  CHECK(s.count(SelRole::Handle) == 2);
  CHECK(s.vertices(SelRole::Handle) == std::vector<int>{2, 3});
  CHECK(s.vertices(SelRole::Fixed) == std::vector<int>{0});
  CHECK_NOTHROW(s.validate(5));
  CHECK_THROWS_WITH(s.validate(6), Contains("a.sel: expected 6 entries (one per mesh vertex), got 5"));
  io_test::check_malformed(dir, [](const std::string& p) { return read_sel(p); }, {
      {"trunc.sel", "# 5 vertices\n0\n1\n2\n",
       "trunc.sel: the header says 5 vertices, the file has 3 entries"},
      {"three.sel", "0\n3\n",
       "three.sel:2: selection value 3 out of range (expected 0 = fixed, 1 = free, 2 = handle)"},
      {"word.sel", "0\nfree\n",
       "word.sel:2: malformed integer 'free'"},
      {"empty.sel", "# nothing\n",
       "empty.sel: no entries"},
  });
  CHECK_THROWS_WITH(read_sel(dir.path("missing.sel")), Contains("missing.sel: cannot open file"));
}

TEST_CASE(".def: 4 x 4 row-major affine matrix, errors", "[io][handles]") {
  const TempDir dir;
  const Eigen::Matrix4d M =
      read_def(dir.write("a.def", "# 4x4 handle transformation matrix\n1 2 3 4\n5 6 7 8\n9 10 11 12\n0 0 0 1\n"));
  CHECK(M(0, 3) == 4.0);
  CHECK(M(2, 0) == 9.0);
  io_test::check_malformed(dir, [](const std::string& p) { return read_def(p); }, {
      {"short.def", "# m\n1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0\n",
       "short.def:5: unexpected end of file (expected matrix entry"},
      {"long.def", "1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n7\n",
       "long.def:5: unexpected data after the 4 x 4 matrix"},
      {"proj.def", "1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 1 0\n",
       "proj.def: last row is (0 0 1 0), expected 0 0 0 1"},
      {"nan.def", "1 0 0 0\n0 nan 0 0\n0 0 1 0\n0 0 0 1\n",
       "nan.def:2: non-finite value 'nan'"},
  });
}

TEST_CASE(".id: groups for linear proxies, rotational clusters and affine patches", "[io][handles]") {
  const TempDir dir;
  const VertexIds lin = read_id(dir.write("lin.id", "2\n0\n2\n5\n0\n"));
  const VertexGroups g = linear_groups_from_ids(lin);
  CHECK(g.label == std::vector<int>{0, 2, 5});
  CHECK(g.members[0] == std::vector<int>{1, 4});
  CHECK(g.members[1] == std::vector<int>{0, 2});
  CHECK(g.group_of == std::vector<int>{1, 0, 1, 2, 0});

  const VertexIds rot = read_id(dir.write("rot.id", "1\n-2\n0\n-1\n-2\n1\n"));
  const VertexGroups r = rotation_groups_from_ids(rot);
  CHECK(r.label == std::vector<int>{0, 1, -1, -2});
  CHECK(r.group_of == std::vector<int>{1, 3, 0, 2, 3, 1});
  CHECK_THROWS_WITH(linear_groups_from_ids(rot), Contains("rot.id: vertex 1 has id -2; linear-group ids must be >= 0"));
  CHECK_THROWS_WITH(affine_patches_from_ids(rot), Contains("affine-patch ids must be >= 0"));

  const VertexGroups a = affine_patches_from_ids(read_id(dir.write("aff.id", "0\n3\n1\n0\n3\n")));
  CHECK(a.label == std::vector<int>{1, 3});
  CHECK(a.group_of == std::vector<int>{-1, 1, 0, -1, 1});

  CHECK_THROWS_WITH(read_id(dir.write("bad.id", "1\n2\n3x\n")), Contains("bad.id:3: malformed integer '3x'"));
  CHECK_THROWS_WITH(read_id(dir.write("empty.id", "\n")), Contains("empty.id: no entries"));
  CHECK_THROWS_WITH(read_id(dir.write("huge.id", "99999999999\n")), Contains("huge.id:1: id 99999999999 out of range"));
}

TEST_CASE(".anim: weights, targets, matrices, errors", "[io][handles]") {
  const TempDir dir;
  const std::string good =
      "2 2 4 2 0 1 0\n"
      "0 1 0 0\n"
      "0 0 0.5 0.5\n"
      "1 2 3 4 5 6\n"
      "7 8 9 10 11 12\n"
      "1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1\n";
  const HandleAnimation a = read_anim(dir.write("a.anim", good));
  CHECK(a.frames == 2);
  CHECK(a.handles() == 2);
  CHECK(a.vertex_count() == 4);
  CHECK(a.weights.coeff(1, 3) == 0.5);
  REQUIRE(a.targets.size() == 2);
  CHECK(a.targets[1].row(1) == Eigen::RowVector3d(10, 11, 12));
  CHECK(a.model.size() == 1);
  CHECK(a.model[0] == Eigen::Matrix4d::Identity());
  CHECK_THROWS_WITH(a.handle_vertices(), Contains("a.anim: handle 1 is not a single vertex with weight 1"));
  CHECK_THROWS_WITH(a.validate(5), Contains("a.anim: expected 5 entries (one per mesh vertex), got 4"));

  io_test::check_malformed(dir, [](const std::string& p) { return read_anim(p); }, {
      {"trunc.anim", good.substr(0, good.find("7 8")),
       "trunc.anim:4: unexpected end of file (expected target coordinate)"},
      {"zero.anim", "1 1 3 1 0 0 0\n0 0 0\n1 2 3\n",
       "zero.anim:2: handle 0 has no nonzero weight"},
      {"extra.anim", "1 1 2 1 0 0 0\n1 0\n1 2 3\n4\n",
       "extra.anim:4: unexpected data after the last of the header's items"},
      {"hdr.anim", "1 1 2\n",
       "hdr.anim:1: unexpected end of file (expected point_lists)"},
      {"neg.anim", "1 -1 2 1 0 0 0\n",
       "negative handles"},
  });
}
