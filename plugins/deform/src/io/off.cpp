// OFF reader and writer; the format is described in mesh_io.h.
#include "format_common.h"

namespace qpreduce::deform {

namespace {

// Checks the keyword: [ST][C][N]OFF; rejects 4OFF, nOFF and anything else.
void check_off_keyword(const detail::TextCursor& cur, std::string_view key) {
  const std::string_view tail = "OFF";
  if (key.size() < tail.size() || key.substr(key.size() - tail.size()) != tail)
    cur.fail(fmt::format("not an OFF file (first token {}, expected OFF or COFF)", detail::shown(key)));
  std::string_view prefix = key.substr(0, key.size() - tail.size());
  if (prefix.find('4') != std::string_view::npos || prefix.find('n') != std::string_view::npos)
    cur.fail(fmt::format("{}: only 3-dimensional OFF is supported", detail::shown(key)));
  if (prefix.substr(0, 2) == "ST") prefix.remove_prefix(2);
  if (!prefix.empty() && prefix[0] == 'C') prefix.remove_prefix(1);
  if (!prefix.empty() && prefix[0] == 'N') prefix.remove_prefix(1);
  if (!prefix.empty()) cur.fail(fmt::format("unknown OFF variant {}", detail::shown(key)));
}

}  // namespace

TriangleMesh read_off(const std::string& path, MeshReadInfo* info) {
  const std::string text = detail::read_file(path);
  detail::TextCursor cur(path, text);
  if (!cur.begin_line()) detail::fail(path, 0, "empty file (expected an OFF header)");
  check_off_keyword(cur, cur.next_on_line());
  std::string_view first = cur.next_on_line();
  if (first == "BINARY") cur.fail("binary OFF is not supported");
  if (first.empty()) {  // counts on the next line
    if (!cur.begin_line()) cur.fail("unexpected end of file (expected the counts 'vertices faces edges')");
    first = cur.next_on_line();
  }
  const long long nv = cur.to_int(first, "vertex count");
  const long long nf = cur.line_int("face count");
  // The edge count, when present, is ignored (it may be non-zero).
  if (nv < 0 || nf < 0) cur.fail(fmt::format("negative count in header ({} vertices, {} faces)", nv, nf));

  std::vector<double> xyz;
  xyz.reserve(3 * detail::capped(nv, 6, text.size()));
  for (long long i = 0; i < nv; ++i) {
    if (!cur.begin_line())
      cur.fail(fmt::format("unexpected end of file after {} of {} vertices", i, nv));
    for (const char* what : {"x coordinate", "y coordinate", "z coordinate"})
      xyz.push_back(cur.line_double(what));
  }
  detail::FaceList faces;
  std::vector<int> corners;
  for (long long f = 0; f < nf; ++f) {
    if (!cur.begin_line()) cur.fail(fmt::format("unexpected end of file after {} of {} faces", f, nf));
    const long long k = cur.line_int("corner count");
    if (k < 3) cur.fail(fmt::format("face with {} corner(s); at least 3 are needed", k));
    corners.clear();
    for (long long c = 0; c < k; ++c) {
      const long long v = cur.line_int("vertex index");
      if (v < 0 || v >= nv) detail::range_error(path, cur.line(), v, nv, 0);
      corners.push_back(static_cast<int>(v));
    }
    faces.add(corners, cur);  // anything after the indices (a color) is ignored
  }
  if (cur.begin_line())
    cur.fail(fmt::format("unexpected data after the {} faces the header announced", nf));
  TriangleMesh mesh;
  mesh.V = detail::vertex_matrix(xyz);
  detail::require_nonempty(path, mesh.V.rows(), faces.triangles(), "faces");
  mesh.F = faces.matrix();
  detail::report(info, "off", faces, mesh);
  return mesh;
}

void write_off(const std::string& path, const TriangleMesh& mesh) {
  check_mesh("write_off", mesh);
  detail::Buffer out;
  fmt::format_to(std::back_inserter(out), "OFF\n{} {} 0\n", mesh.V.rows(), mesh.F.rows());
  for (Index i = 0; i < mesh.V.rows(); ++i) detail::put_xyz(out, "", mesh.V, i, "");
  detail::put_rows(out, "3 ", mesh.F, 0, "");
  detail::write_buffer(path, out);
}

}  // namespace qpreduce::deform
