// MEDIT and TetGen readers and writers; the formats are described in tet_io.h.
#include "qpreduce/deform/io/tet_io.h"

#include "format_common.h"

#include <algorithm>
#include <cctype>

namespace qpreduce::deform {

namespace {

bool same_keyword(std::string_view a, std::string_view b) {
  return a.size() == b.size() && std::equal(a.begin(), a.end(), b.begin(), [](char x, char y) {
           return std::tolower(static_cast<unsigned char>(x)) == std::tolower(static_cast<unsigned char>(y));
         });
}

// MEDIT sections that are read and dropped, with the numbers per record.
struct SkippedSection {
  const char* name;
  int tokens;
};
constexpr SkippedSection kSkipped[] = {
    {"Edges", 3},           {"Quadrilaterals", 5},           {"Hexahedra", 9},       {"Prisms", 7},
    {"Pyramids", 6},        {"Corners", 1},                  {"Ridges", 1},          {"RequiredVertices", 1},
    {"RequiredEdges", 1},   {"RequiredTriangles", 1},        {"Normals", 3},         {"NormalAtVertices", 2},
    {"NormalAtTriangleVertices", 3}, {"Tangents", 3},        {"TangentAtVertices", 2},
    {"TangentAtEdgeVertices", 3}};

long long section_count(detail::TextCursor& cur, std::string_view section) {
  const long long n = cur.read_int("section size");
  if (n < 0) cur.fail(fmt::format("negative size {} for section '{}'", n, section));
  return n;
}

void require_more(detail::TextCursor& cur, long long i, long long n, const char* what) {
  if (cur.at_end()) cur.fail(fmt::format("unexpected end of file after {} of {} {}", i, n, what));
}

// K 1-based indices and a reference number per record.
template <int K>
void read_medit_elements(detail::TextCursor& cur, long long n, const char* what, detail::ElementList<K>& out) {
  int corners[K];
  for (long long i = 0; i < n; ++i) {
    require_more(cur, i, n, what);
    for (int k = 0; k < K; ++k) {
      const long long v = cur.read_int("vertex index") - 1;
      if (v < 0) cur.fail(fmt::format("vertex index {} (MEDIT indices start at 1)", v + 1));
      if (v > std::numeric_limits<int>::max()) cur.fail(fmt::format("vertex index {} too large", v + 1));
      corners[k] = static_cast<int>(v);
    }
    out.add(corners, cur.line());
    cur.read_int("reference number");
  }
}

void report_tets(MeshReadInfo* info, const char* format, const TetMesh& mesh, std::vector<std::string> notes) {
  if (info == nullptr) return;
  *info = MeshReadInfo{};
  info->format = format;
  info->unreferenced_vertices = detail::count_unreferenced(mesh.V.rows(), mesh.T);
  info->notes = std::move(notes);
  if (info->unreferenced_vertices > 0)
    info->notes.push_back(fmt::format("{} vertex(es) used by no tetrahedron (kept)", info->unreferenced_vertices));
}

}  // namespace

TetMesh read_medit(const std::string& path, MeshReadInfo* info) {
  const std::string text = detail::read_file(path);
  detail::TextCursor cur(path, text);
  std::vector<double> xyz;
  detail::ElementList<3> triangles;
  detail::ElementList<4> tets;
  std::vector<std::string> notes;
  bool have_vertices = false, have_tets = false;
  for (std::string_view key = cur.next(); !key.empty(); key = cur.next()) {
    if (same_keyword(key, "End")) break;
    if (same_keyword(key, "MeshVersionFormatted")) {
      cur.read_int("mesh version");
    } else if (same_keyword(key, "Dimension")) {
      const long long d = cur.read_int("dimension");
      if (d != 3) cur.fail(fmt::format("Dimension {}: only 3-dimensional meshes are supported", d));
    } else if (same_keyword(key, "Vertices")) {
      if (have_vertices) cur.fail("second Vertices section");
      have_vertices = true;
      const long long n = section_count(cur, key);
      xyz.reserve(3 * detail::capped(n, 8, text.size()));
      for (long long i = 0; i < n; ++i) {
        require_more(cur, i, n, "vertices");
        for (const char* what : {"x coordinate", "y coordinate", "z coordinate"}) xyz.push_back(cur.read_double(what));
        cur.read_int("reference number");
      }
    } else if (same_keyword(key, "Triangles")) {
      read_medit_elements(cur, section_count(cur, key), "triangles", triangles);
    } else if (same_keyword(key, "Tetrahedra")) {
      have_tets = true;
      read_medit_elements(cur, section_count(cur, key), "tetrahedra", tets);
    } else {
      const SkippedSection* skip =
          std::find_if(std::begin(kSkipped), std::end(kSkipped),
                       [&](const SkippedSection& s) { return same_keyword(key, s.name); });
      if (skip == std::end(kSkipped))
        cur.fail(fmt::format("unknown MEDIT section {} (cannot skip it: record size unknown)", detail::shown(key)));
      const long long n = section_count(cur, key);
      for (long long i = 0; i < n; ++i) {
        require_more(cur, i, n, skip->name);
        for (int k = 0; k < skip->tokens; ++k) cur.read_double(skip->name);
      }
      if (n > 0) notes.push_back(fmt::format("skipped {} {}", n, skip->name));
    }
  }
  TetMesh mesh;
  mesh.V = detail::vertex_matrix(xyz);
  if (!have_tets) detail::fail(path, 0, "no Tetrahedra section (degenerate input)");
  detail::require_nonempty(path, mesh.V.rows(), tets.rows(), "tetrahedra");
  tets.check_range(path, mesh.V.rows(), 1);
  triangles.check_range(path, mesh.V.rows(), 1);
  mesh.T = tets.matrix();
  mesh.F = triangles.matrix();
  report_tets(info, "medit", mesh, std::move(notes));
  return mesh;
}

namespace {

// One TetGen file: a header line, then `count` lines of exactly `columns`
// tokens whose first is a consecutive id; `row(tokens)` reads each.
class TetgenFile {
 public:
  explicit TetgenFile(const std::string& path) : text_(detail::read_file(path)), cur_(path, text_) {
    if (!cur_.begin_line()) detail::fail(path, 0, "empty file (expected a header line)");
    cur_.split_line(header_);
  }
  long long header(std::size_t i, const char* what, long long fallback) const {
    if (i >= header_.size()) {
      if (fallback >= 0) return fallback;
      cur_.fail(fmt::format("header is missing the {}", what));
    }
    const long long v = cur_.to_int(header_[i], what);
    if (v < 0) cur_.fail(fmt::format("negative {} {} in header", what, v));
    return v;
  }
  template <typename Row>
  void rows(long long count, std::size_t columns, const char* what, Row&& row) {
    std::vector<std::string_view> tokens;
    long long first_id = 0;
    for (long long i = 0; i < count; ++i) {
      if (!cur_.begin_line()) cur_.fail(fmt::format("unexpected end of file after {} of {} {}", i, count, what));
      cur_.split_line(tokens);
      if (tokens.size() != columns)
        cur_.fail(fmt::format("expected {} columns, got {}", columns, tokens.size()));
      const long long id = cur_.to_int(tokens[0], "id");
      if (i == 0) first_id = id;
      if (i == 0 && id != 0 && id != 1) cur_.fail(fmt::format("first id is {} (expected 0 or 1)", id));
      if (id != first_id + i) cur_.fail(fmt::format("id {} out of sequence (expected {})", id, first_id + i));
      row(tokens);
    }
    if (cur_.begin_line()) cur_.fail(fmt::format("unexpected data after the {} {} the header announced", count, what));
    first_id_ = first_id;
  }
  long long first_id() const { return first_id_; }
  const detail::TextCursor& cursor() const { return cur_; }

 private:
  std::string text_;
  detail::TextCursor cur_;
  std::vector<std::string_view> header_;
  long long first_id_ = 0;
};

// Corner `token` of a TetGen element, shifted by `base` and checked.
int tetgen_corner(const detail::TextCursor& cur, std::string_view token, int base, Index vertex_count) {
  const long long v = cur.to_int(token, "vertex index") - base;
  if (v < 0 || v >= vertex_count) detail::range_error(cur.file(), cur.line(), v, vertex_count, base);
  return static_cast<int>(v);
}

std::string tetgen_prefix(const std::string& path) {
  const std::string ext = detail::lower_extension(path);
  return ext == ".node" || ext == ".ele" || ext == ".face" ? detail::strip_extension(path) : path;
}

}  // namespace

TetMesh read_tetgen(const std::string& path, MeshReadInfo* info) {
  const std::string prefix = tetgen_prefix(path);
  std::vector<std::string> notes;
  TetMesh mesh;

  TetgenFile node(prefix + ".node");
  const long long n = node.header(0, "node count", -1);
  if (node.header(1, "dimension", 3) != 3) node.cursor().fail("only 3-dimensional .node files are supported");
  const long long nattr = node.header(2, "attribute count", 0), nmarker = node.header(3, "marker count", 0);
  if (nmarker > 1) node.cursor().fail("marker count must be 0 or 1");
  if (n == 0) node.cursor().fail("no nodes (degenerate input; points in a .poly file are not supported)");
  std::vector<double> xyz;
  node.rows(n, static_cast<std::size_t>(4 + nattr + nmarker), "nodes", [&](const auto& t) {
    for (int k = 1; k <= 3; ++k) xyz.push_back(node.cursor().to_double(t[k], "coordinate"));
  });
  mesh.V = detail::vertex_matrix(xyz);
  const int base = static_cast<int>(node.first_id());

  TetgenFile ele(prefix + ".ele");
  const long long m = ele.header(0, "tetrahedron count", -1);
  const long long corners = ele.header(1, "nodes per tetrahedron", 4), eattr = ele.header(2, "attribute count", 0);
  if (corners != 4 && corners != 10) ele.cursor().fail(fmt::format("{} nodes per tetrahedron (expected 4 or 10)", corners));
  if (corners == 10) notes.push_back("quadratic tetrahedra: kept their 4 corners");
  detail::ElementList<4> tets;
  ele.rows(m, static_cast<std::size_t>(1 + corners + eattr), "tetrahedra", [&](const auto& t) {
    int c[4];
    for (int k = 0; k < 4; ++k) c[k] = tetgen_corner(ele.cursor(), t[k + 1], base, mesh.V.rows());
    tets.add(c, ele.cursor().line());
  });
  detail::require_nonempty(prefix + ".ele", mesh.V.rows(), tets.rows(), "tetrahedra");
  mesh.T = tets.matrix();

  if (detail::file_exists(prefix + ".face")) {
    TetgenFile face(prefix + ".face");
    const long long k = face.header(0, "face count", -1), fmarker = face.header(1, "marker count", 0);
    if (fmarker > 1) face.cursor().fail("marker count must be 0 or 1");
    detail::ElementList<3> tris;
    face.rows(k, static_cast<std::size_t>(4 + fmarker), "faces", [&](const auto& t) {
      int c[3];
      for (int j = 0; j < 3; ++j) c[j] = tetgen_corner(face.cursor(), t[j + 1], base, mesh.V.rows());
      tris.add(c, face.cursor().line());
    });
    mesh.F = tris.matrix();
  }
  report_tets(info, "tetgen", mesh, std::move(notes));
  return mesh;
}

TetMesh read_tet_mesh(const std::string& path, MeshReadInfo* info) {
  const std::string ext = detail::lower_extension(path);
  if (ext == ".mesh") return read_medit(path, info);
  if (ext == ".node" || ext == ".ele") return read_tetgen(path, info);
  detail::fail(path, 0, fmt::format("unsupported tet mesh extension '{}' (expected .mesh, .node or .ele)", ext));
}

void write_medit(const std::string& path, const TetMesh& mesh) {
  check_mesh("write_medit", mesh);
  detail::Buffer out;
  fmt::format_to(std::back_inserter(out), "MeshVersionFormatted 1\nDimension 3\nVertices\n{}\n", mesh.V.rows());
  for (Index i = 0; i < mesh.V.rows(); ++i) detail::put_xyz(out, "", mesh.V, i, " 0");
  if (mesh.F.rows() > 0) {
    fmt::format_to(std::back_inserter(out), "Triangles\n{}\n", mesh.F.rows());
    detail::put_rows(out, "", mesh.F, 1, " 0");
  }
  fmt::format_to(std::back_inserter(out), "Tetrahedra\n{}\n", mesh.T.rows());
  detail::put_rows(out, "", mesh.T, 1, " 0");
  fmt::format_to(std::back_inserter(out), "End\n");
  detail::write_buffer(path, out);
}

namespace {
template <typename Rows>
void put_numbered(detail::Buffer& out, const Rows& rows, const char* suffix) {
  for (Index i = 0; i < rows.rows(); ++i) {
    fmt::format_to(std::back_inserter(out), "{}", i);
    for (Index j = 0; j < rows.cols(); ++j) fmt::format_to(std::back_inserter(out), " {}", rows(i, j));
    fmt::format_to(std::back_inserter(out), "{}\n", suffix);
  }
}
}  // namespace

void write_tetgen(const std::string& path, const TetMesh& mesh) {
  check_mesh("write_tetgen", mesh);
  const std::string prefix = tetgen_prefix(path);
  detail::Buffer node, ele, face;
  fmt::format_to(std::back_inserter(node), "{} 3 0 0\n", mesh.V.rows());
  put_numbered(node, mesh.V, "");
  fmt::format_to(std::back_inserter(ele), "{} 4 0\n", mesh.T.rows());
  put_numbered(ele, mesh.T, "");
  auto bytes = [](const detail::Buffer& b) { return std::string_view(b.data(), b.size()); };
  std::vector<std::pair<std::string, std::string_view>> files{{prefix + ".node", bytes(node)},
                                                              {prefix + ".ele", bytes(ele)}};
  if (mesh.F.rows() > 0) {
    fmt::format_to(std::back_inserter(face), "{} 1\n", mesh.F.rows());
    put_numbered(face, mesh.F, " 1");
    files.emplace_back(prefix + ".face", bytes(face));
  }
  // The three files describe one mesh: all of them or, on a failure, none.
  detail::write_files(files);
}

void write_tet_mesh(const std::string& path, const TetMesh& mesh) {
  const std::string ext = detail::lower_extension(path);
  if (ext == ".mesh") return write_medit(path, mesh);
  if (ext == ".node") return write_tetgen(path, mesh);
  detail::fail(path, 0, fmt::format("unsupported tet mesh extension '{}' (expected .mesh or .node)", ext));
}

}  // namespace qpreduce::deform
