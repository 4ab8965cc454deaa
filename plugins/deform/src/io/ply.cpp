// PLY reader (ASCII, binary little-endian) and writer; the format is
// described in mesh_io.h.
#include "format_common.h"

#include <cmath>
#include <cstdint>
#include <cstring>

namespace qpreduce::deform {

namespace {

enum class PlyType { Int8, UInt8, Int16, UInt16, Int32, UInt32, Float32, Float64 };

struct PlyProperty {
  std::string name;
  PlyType type = PlyType::Float32;  // the item type, for a list
  bool list = false;
  PlyType count_type = PlyType::UInt8;
};

struct PlyElement {
  std::string name;
  long long count = 0;
  std::vector<PlyProperty> properties;
};

struct PlyHeader {
  bool binary = false;
  std::vector<PlyElement> elements;
  std::size_t body_offset = 0;  // first byte after the end_header line
  long body_line = 0;           // its line number
};

bool is_integer(PlyType t) { return t != PlyType::Float32 && t != PlyType::Float64; }

std::size_t type_size(PlyType t) {
  switch (t) {
    case PlyType::Int8: case PlyType::UInt8: return 1;
    case PlyType::Int16: case PlyType::UInt16: return 2;
    case PlyType::Int32: case PlyType::UInt32: case PlyType::Float32: return 4;
    case PlyType::Float64: return 8;
  }
  return 0;
}

PlyType parse_type(const detail::TextCursor& cur, std::string_view name) {
  struct Entry { const char* a; const char* b; PlyType t; };
  static const Entry table[] = {
      {"char", "int8", PlyType::Int8},     {"uchar", "uint8", PlyType::UInt8},
      {"short", "int16", PlyType::Int16},  {"ushort", "uint16", PlyType::UInt16},
      {"int", "int32", PlyType::Int32},    {"uint", "uint32", PlyType::UInt32},
      {"float", "float32", PlyType::Float32}, {"double", "float64", PlyType::Float64}};
  for (const Entry& e : table)
    if (name == e.a || name == e.b) return e.t;
  cur.fail(fmt::format("unknown PLY property type {}", detail::shown(name)));
}

std::string_view required(detail::TextCursor& cur, const char* what) {
  const std::string_view t = cur.next_on_line();
  if (t.empty()) cur.fail(fmt::format("missing {}", what));
  return t;
}

PlyHeader parse_header(const std::string& path, const std::string& text) {
  if (text.compare(0, 3, "ply") != 0 || (text.size() > 3 && text[3] != '\n' && text[3] != '\r'))
    detail::fail(path, 1, "not a PLY file (missing 'ply' magic line)");
  detail::TextCursor cur(path, text, 1, '\0');
  cur.begin_line();  // "ply"
  PlyHeader h;
  bool have_format = false;
  while (cur.begin_line()) {
    const std::string_view key = cur.next_on_line();
    if (key == "format") {
      const std::string_view format = required(cur, "format name");
      if (format == "binary_big_endian")
        cur.fail("binary_big_endian PLY is not supported (only ascii and binary_little_endian)");
      if (format != "ascii" && format != "binary_little_endian")
        cur.fail(fmt::format("unknown PLY format {}", detail::shown(format)));
      h.binary = format == "binary_little_endian";
      have_format = true;
    } else if (key == "comment" || key == "obj_info") {
      continue;
    } else if (key == "element") {
      PlyElement e;
      e.name = std::string(required(cur, "element name"));
      e.count = cur.line_int("element count");
      if (e.count < 0) cur.fail(fmt::format("negative count {} for element '{}'", e.count, e.name));
      h.elements.push_back(std::move(e));
    } else if (key == "property") {
      if (h.elements.empty()) cur.fail("property before any element");
      PlyProperty p;
      std::string_view type = required(cur, "property type");
      if (type == "list") {
        p.list = true;
        p.count_type = parse_type(cur, required(cur, "list count type"));
        if (!is_integer(p.count_type)) cur.fail("list count type must be an integer type");
        type = required(cur, "list item type");
      }
      p.type = parse_type(cur, type);
      p.name = std::string(required(cur, "property name"));
      h.elements.back().properties.push_back(std::move(p));
    } else if (key == "end_header") {
      if (!have_format) cur.fail("header has no 'format' line");
      const std::size_t eol = text.find('\n', cur.offset());
      h.body_offset = eol == std::string::npos ? text.size() : eol + 1;
      h.body_line = cur.line() + 1;
      return h;
    } else {
      cur.fail(fmt::format("unexpected PLY header line starting with {}", detail::shown(key)));
    }
  }
  detail::fail(path, 0, "PLY header has no end_header line");
}

// The two encodings of a PLY body behind one small interface:
//   real(type) / integer(type) read one value, skip(type) drops one,
//   at(element, instance) names the place for error messages,
//   finish() rejects data after the last element.
class AsciiBody {
 public:
  AsciiBody(const std::string& path, const std::string& text, const PlyHeader& h)
      : cur_(path, std::string_view(text).substr(h.body_offset), h.body_line, '\0') {}
  void at(const PlyElement& e, long long i) { element_ = &e, instance_ = i; }
  double real(PlyType, const char* what) { return cur_.to_double(token(what), what); }
  long long integer(PlyType, const char* what) { return cur_.to_int(token(what), what); }
  void skip(PlyType) { token("property value"); }
  [[noreturn]] void fail(const std::string& problem) const { cur_.fail(problem); }
  long line() const { return cur_.line(); }
  void finish() {
    if (!cur_.at_end())
      cur_.fail(fmt::format("unexpected data after the last element ({})", detail::shown(cur_.next())));
  }

 private:
  std::string_view token(const char* what) {
    const std::string_view t = cur_.next();
    if (t.empty())
      cur_.fail(fmt::format("unexpected end of file in element '{}' ({} of {}; expected {})", element_->name,
                            instance_, element_->count, what));
    return t;
  }
  detail::TextCursor cur_;
  const PlyElement* element_ = nullptr;
  long long instance_ = 0;
};

class BinaryLittleEndianBody {
 public:
  BinaryLittleEndianBody(const std::string& path, const std::string& text, const PlyHeader& h)
      : path_(path),
        begin_(reinterpret_cast<const unsigned char*>(text.data())),
        p_(begin_ + h.body_offset),
        end_(begin_ + text.size()) {}
  void at(const PlyElement& e, long long i) { element_ = &e, instance_ = i; }
  double real(PlyType t, const char* what) {
    const double v = value(t);
    if (!std::isfinite(v)) fail(fmt::format("non-finite value ({})", what));
    return v;
  }
  long long integer(PlyType t, const char*) { return static_cast<long long>(value(t)); }
  void skip(PlyType t) { take(type_size(t)); }
  [[noreturn]] void fail(const std::string& problem) const {
    detail::fail(path_, 0, fmt::format("{} (byte offset {})", problem, p_ - begin_));
  }
  long line() const { return 0; }
  void finish() {
    for (const unsigned char* q = p_; q < end_; ++q)
      if (!std::isspace(*q)) fail(fmt::format("{} unexpected byte(s) after the last element", end_ - p_));
  }

 private:
  const unsigned char* take(std::size_t n) {
    if (static_cast<std::size_t>(end_ - p_) < n)
      fail(fmt::format("unexpected end of file in element '{}' ({} of {})", element_->name, instance_,
                       element_->count));
    const unsigned char* q = p_;
    p_ += n;
    return q;
  }
  template <typename U>
  U load() {
    const unsigned char* q = take(sizeof(U));
    U u = 0;
    for (std::size_t i = 0; i < sizeof(U); ++i) u = static_cast<U>(u | static_cast<U>(q[i]) << (8 * i));
    return u;
  }
  template <typename T, typename U>
  double as() {
    const U u = load<U>();
    T t;
    std::memcpy(&t, &u, sizeof t);
    return static_cast<double>(t);
  }
  double value(PlyType t) {
    switch (t) {
      case PlyType::Int8: return as<std::int8_t, std::uint8_t>();
      case PlyType::UInt8: return as<std::uint8_t, std::uint8_t>();
      case PlyType::Int16: return as<std::int16_t, std::uint16_t>();
      case PlyType::UInt16: return as<std::uint16_t, std::uint16_t>();
      case PlyType::Int32: return as<std::int32_t, std::uint32_t>();
      case PlyType::UInt32: return as<std::uint32_t, std::uint32_t>();
      case PlyType::Float32: return as<float, std::uint32_t>();
      case PlyType::Float64: return as<double, std::uint64_t>();
    }
    return 0.0;
  }

  std::string path_;
  const unsigned char* begin_;
  const unsigned char* p_;
  const unsigned char* end_;
  const PlyElement* element_ = nullptr;
  long long instance_ = 0;
};

struct PlyLayout {
  const PlyElement* vertex = nullptr;
  const PlyElement* face = nullptr;
  int xyz[3] = {-1, -1, -1};  // property positions of x, y, z in `vertex`
  int indices = -1;           // position of the vertex index list in `face`
};

PlyLayout find_layout(const std::string& path, const PlyHeader& h) {
  PlyLayout L;
  for (const PlyElement& e : h.elements) {
    if (e.name == "vertex" && L.vertex == nullptr) L.vertex = &e;
    if (e.name == "face" && L.face == nullptr) L.face = &e;
  }
  if (L.vertex == nullptr) detail::fail(path, 0, "PLY header has no 'vertex' element");
  if (L.face == nullptr) detail::fail(path, 0, "PLY header has no 'face' element (no faces: degenerate input)");
  const char* axes[3] = {"x", "y", "z"};
  for (std::size_t p = 0; p < L.vertex->properties.size(); ++p) {
    const PlyProperty& prop = L.vertex->properties[p];
    for (int a = 0; a < 3; ++a)
      if (prop.name == axes[a] && !prop.list) L.xyz[a] = static_cast<int>(p);
  }
  for (int a = 0; a < 3; ++a)
    if (L.xyz[a] < 0) detail::fail(path, 0, fmt::format("PLY vertex element has no scalar property '{}'", axes[a]));
  for (std::size_t p = 0; p < L.face->properties.size(); ++p) {
    const PlyProperty& prop = L.face->properties[p];
    if (prop.list && (prop.name == "vertex_indices" || prop.name == "vertex_index")) {
      if (!is_integer(prop.type)) detail::fail(path, 0, "PLY vertex indices must have an integer type");
      L.indices = static_cast<int>(p);
    }
  }
  if (L.indices < 0)
    detail::fail(path, 0, "PLY face element has no list property 'vertex_indices' or 'vertex_index'");
  return L;
}

template <typename Body>
TriangleMesh read_body(const std::string& path, const std::string& text, const PlyHeader& h, Body body,
                       detail::FaceList& faces) {
  const PlyLayout L = find_layout(path, h);
  std::vector<double> xyz;
  xyz.reserve(3 * detail::capped(L.vertex->count, 6, text.size()));
  std::vector<int> corners;
  for (const PlyElement& e : h.elements) {
    const bool is_vertex = &e == L.vertex, is_face = &e == L.face;
    if (e.properties.empty()) continue;  // nothing to read, however large the count
    for (long long i = 0; i < e.count; ++i) {
      body.at(e, i);
      double point[3] = {0.0, 0.0, 0.0};
      for (std::size_t p = 0; p < e.properties.size(); ++p) {
        const PlyProperty& prop = e.properties[p];
        const int q = static_cast<int>(p);
        if (prop.list) {
          const long long k = body.integer(prop.count_type, "list length");
          if (k < 0) body.fail(fmt::format("negative list length {}", k));
          if (is_face && q == L.indices) {
            corners.clear();
            for (long long c = 0; c < k; ++c) {
              const long long v = body.integer(prop.type, "vertex index");
              if (v < 0 || v >= L.vertex->count) detail::range_error(path, body.line(), v, L.vertex->count, 0);
              corners.push_back(static_cast<int>(v));
            }
            faces.add(corners, path, body.line());
          } else {
            for (long long c = 0; c < k; ++c) body.skip(prop.type);
          }
        } else if (is_vertex && (q == L.xyz[0] || q == L.xyz[1] || q == L.xyz[2])) {
          const int axis = q == L.xyz[0] ? 0 : q == L.xyz[1] ? 1 : 2;
          point[axis] = body.real(prop.type, "vertex coordinate");
        } else {
          body.skip(prop.type);
        }
      }
      if (is_vertex) xyz.insert(xyz.end(), point, point + 3);
    }
  }
  body.finish();
  TriangleMesh mesh;
  mesh.V = detail::vertex_matrix(xyz);
  detail::require_nonempty(path, mesh.V.rows(), faces.triangles(), "faces");
  mesh.F = faces.matrix();
  return mesh;
}

template <typename T, typename U>
void put_le(detail::Buffer& out, T value) {
  U u;
  std::memcpy(&u, &value, sizeof u);
  for (std::size_t i = 0; i < sizeof(U); ++i) out.push_back(static_cast<char>((u >> (8 * i)) & 0xFFu));
}

}  // namespace

TriangleMesh read_ply(const std::string& path, MeshReadInfo* info) {
  const std::string text = detail::read_file(path);
  const PlyHeader h = parse_header(path, text);
  detail::FaceList faces;
  TriangleMesh mesh = h.binary ? read_body(path, text, h, BinaryLittleEndianBody(path, text, h), faces)
                               : read_body(path, text, h, AsciiBody(path, text, h), faces);
  detail::report(info, h.binary ? "ply-binary-le" : "ply-ascii", faces, mesh);
  return mesh;
}

void write_ply(const std::string& path, const TriangleMesh& mesh, PlyEncoding encoding) {
  check_mesh("write_ply", mesh);
  const bool binary = encoding == PlyEncoding::BinaryLittleEndian;
  detail::Buffer out;
  fmt::format_to(std::back_inserter(out),
                 "ply\nformat {} 1.0\ncomment qpreduce\nelement vertex {}\nproperty double x\n"
                 "property double y\nproperty double z\nelement face {}\n"
                 "property list uchar int vertex_indices\nend_header\n",
                 binary ? "binary_little_endian" : "ascii", mesh.V.rows(), mesh.F.rows());
  if (binary) {
    for (Index i = 0; i < mesh.V.rows(); ++i)
      for (Index j = 0; j < 3; ++j) put_le<double, std::uint64_t>(out, mesh.V(i, j));
    for (Index i = 0; i < mesh.F.rows(); ++i) {
      out.push_back(static_cast<char>(3));
      for (Index j = 0; j < 3; ++j) put_le<std::int32_t, std::uint32_t>(out, mesh.F(i, j));
    }
  } else {
    for (Index i = 0; i < mesh.V.rows(); ++i) detail::put_xyz(out, "", mesh.V, i, "");
    detail::put_rows(out, "3 ", mesh.F, 0, "");
  }
  detail::write_buffer(path, out);
}

}  // namespace qpreduce::deform
