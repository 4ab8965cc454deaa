// mesh_file_kind: the extension decides, in any case, as in the readers.
#include <catch2/catch.hpp>

#include "qpreduce/deform/io/file_kind.h"

using namespace qpreduce::deform;

TEST_CASE("mesh_file_kind: surfaces and tets by extension, case-insensitive", "[io][file_kind]") {
  for (const char* p : {"a.obj", "dir/b.OFF", "c.Ply", "d.x.OBJ"}) CHECK(mesh_file_kind(p) == MeshFileKind::Surface);
  for (const char* p : {"a.mesh", "dir/b.NODE", "c.Ele", "d.MESH"}) CHECK(mesh_file_kind(p) == MeshFileKind::Tets);
  for (const char* p : {"a", "a.stl", "dir.obj/b", "a.obj.gz", ""}) CHECK(mesh_file_kind(p) == MeshFileKind::Unknown);
  CHECK(lower_case_extension("dir/Mesh.OBJ") == ".obj");
  CHECK(lower_case_extension("dir/mesh").empty());
}
