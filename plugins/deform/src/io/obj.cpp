// OBJ reader and writer; the format is described in mesh_io.h.
#include "format_common.h"

namespace qpreduce::deform {

namespace {

// The vertex index of an OBJ corner `i`, `i/t`, `i/t/n` or `i//n`, 0-based.
// Relative indices (< 0) resolve against the `vertices_so_far`.
int obj_corner(const detail::TextCursor& cur, std::string_view token, Index vertices_so_far) {
  const std::string_view head = token.substr(0, token.find('/'));
  if (head.empty()) cur.fail(fmt::format("face corner {} has no vertex index", detail::shown(token)));
  const long long i = cur.to_int(head, "vertex index");
  if (i == 0) cur.fail("vertex index 0 (OBJ indices start at 1; negative ones are relative)");
  const long long zero_based = i > 0 ? i - 1 : vertices_so_far + i;
  if (zero_based < 0)
    cur.fail(fmt::format("relative vertex index {} refers before the first vertex ({} read so far)", i,
                         vertices_so_far));
  if (zero_based > std::numeric_limits<int>::max()) cur.fail(fmt::format("vertex index {} too large", i));
  return static_cast<int>(zero_based);
}

}  // namespace

TriangleMesh read_obj(const std::string& path, MeshReadInfo* info) {
  const std::string text = detail::read_file(path);
  detail::TextCursor cur(path, text);
  std::vector<double> xyz;
  detail::FaceList faces;
  std::vector<int> corners;
  Index ignored_lines = 0, ignored_points = 0;
  while (cur.begin_line()) {
    const std::string_view key = cur.next_on_line();
    if (key == "v") {
      for (const char* what : {"x coordinate", "y coordinate", "z coordinate"})
        xyz.push_back(cur.line_double(what));
    } else if (key == "f") {
      corners.clear();
      const Index n = static_cast<Index>(xyz.size() / 3);
      for (std::string_view t = cur.next_on_line(); !t.empty(); t = cur.next_on_line())
        corners.push_back(obj_corner(cur, t, n));
      faces.add(corners, cur);
    } else if (key == "l") {
      ++ignored_lines;
    } else if (key == "p") {
      ++ignored_points;
    }
    // vt, vn, vp, g, o, s, usemtl, mtllib and unknown keywords: ignored.
  }
  TriangleMesh mesh;
  mesh.V = detail::vertex_matrix(xyz);
  detail::require_nonempty(path, mesh.V.rows(), faces.triangles(), "faces");
  faces.check_range(path, mesh.V.rows(), 1);
  mesh.F = faces.matrix();
  detail::report(info, "obj", faces, mesh);
  if (info != nullptr && ignored_lines + ignored_points > 0)
    info->notes.push_back(
        fmt::format("ignored {} polyline ('l') and {} point ('p') element(s)", ignored_lines, ignored_points));
  return mesh;
}

void write_obj(const std::string& path, const TriangleMesh& mesh) {
  check_mesh("write_obj", mesh);
  detail::Buffer out;
  fmt::format_to(std::back_inserter(out), "# qpreduce: {} vertices, {} triangles\n", mesh.V.rows(),
                 mesh.F.rows());
  for (Index i = 0; i < mesh.V.rows(); ++i) detail::put_xyz(out, "v ", mesh.V, i, "");
  detail::put_rows(out, "f ", mesh.F, 1, "");
  detail::write_buffer(path, out);
}

}  // namespace qpreduce::deform
