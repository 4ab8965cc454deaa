// Whole-file input, the text cursor, strict number parsing, triangulation and
// buffered output shared by the readers and writers; see format_common.h.
#include "format_common.h"

#include "qpreduce/util/atomic_file.h"

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <system_error>

namespace qpreduce::deform {

namespace detail {

void fail(const std::string& file, long line, const std::string& problem) {
  throw IoError(file, line, problem);
}

std::string read_file(const std::string& path) {
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec)) fail(path, 0, "cannot open file (it is a directory)");
  std::ifstream in(path, std::ios::binary);
  if (!in) fail(path, 0, fmt::format("cannot open file ({})", std::strerror(errno)));
  std::ostringstream buffer;
  buffer << in.rdbuf();
  if (in.bad()) fail(path, 0, "read error");
  return std::move(buffer).str();
}

void write_file(const std::string& path, std::string_view bytes) {
  try {
    write_file_atomically(path, bytes);
  } catch (const FileError& e) {
    fail(e.file(), e.line(), e.problem());
  }
}

void write_files(const std::vector<std::pair<std::string, std::string_view>>& files) {
  try {
    write_files_atomically(files);
  } catch (const FileError& e) {
    fail(e.file(), e.line(), e.problem());
  }
}

std::string lower_extension(const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return ext;
}

std::string strip_extension(const std::string& path) {
  std::filesystem::path p(path);
  return p.replace_extension().string();
}

bool file_exists(const std::string& path) {
  std::error_code ec;
  return std::filesystem::is_regular_file(path, ec);
}

// ---- TextCursor ----

TextCursor::TextCursor(std::string file, std::string_view text, long first_line, char comment)
    : file_(std::move(file)), text_(text), line_(first_line), token_line_(first_line), comment_(comment) {
  // A UTF-8 byte-order mark (editors on Windows write one) is not data.
  constexpr std::string_view kBom = "\xEF\xBB\xBF";
  if (text_.substr(0, kBom.size()) == kBom) pos_ = kBom.size();
}

std::string shown(std::string_view token) {
  constexpr std::size_t kShownBytes = 40;  // a longer token is cut: a 1 MB line must not fill the terminal
  std::string s;
  for (std::size_t i = 0; i < token.size() && i < kShownBytes; ++i) {
    const unsigned char c = static_cast<unsigned char>(token[i]);
    if (c >= 0x20 && c < 0x7f)
      s += static_cast<char>(c);
    else
      s += fmt::format("\\x{:02X}", c);
  }
  if (token.size() > kShownBytes) return fmt::format("'{}…' ({} bytes)", s, token.size());
  return "'" + s + "'";
}

void TextCursor::skip_blanks_on_line() {
  while (pos_ < text_.size()) {
    const char c = text_[pos_];
    if (c == ' ' || c == '\t' || c == '\r' || c == '\f' || c == '\v') {
      ++pos_;
    } else if (comment_ != '\0' && c == comment_) {
      while (pos_ < text_.size() && text_[pos_] != '\n') ++pos_;
    } else {
      return;
    }
  }
}

std::string_view TextCursor::take_token() {
  const std::size_t start = pos_;
  while (pos_ < text_.size()) {
    const char c = text_[pos_];
    if (std::isspace(static_cast<unsigned char>(c)) || (comment_ != '\0' && c == comment_)) break;
    ++pos_;
  }
  token_line_ = line_;
  at_line_start_ = false;
  return text_.substr(start, pos_ - start);
}

std::string_view TextCursor::next() {
  for (;;) {
    skip_blanks_on_line();
    if (pos_ >= text_.size()) return {};  // line() stays that of the last token
    if (text_[pos_] != '\n') return take_token();
    ++pos_;
    ++line_;
  }
}

bool TextCursor::begin_line() {
  if (!at_line_start_) {
    while (pos_ < text_.size() && text_[pos_] != '\n') ++pos_;
  }
  for (;;) {
    if (pos_ < text_.size() && text_[pos_] == '\n') {
      ++pos_;
      ++line_;
    }
    skip_blanks_on_line();
    if (pos_ >= text_.size()) {
      at_line_start_ = true;
      return false;
    }
    if (text_[pos_] != '\n') {
      token_line_ = line_;
      at_line_start_ = false;
      return true;
    }
  }
}

std::string_view TextCursor::next_on_line() {
  skip_blanks_on_line();
  if (pos_ >= text_.size() || text_[pos_] == '\n') return {};
  return take_token();
}

void TextCursor::split_line(std::vector<std::string_view>& tokens) {
  tokens.clear();
  for (std::string_view t = next_on_line(); !t.empty(); t = next_on_line()) tokens.push_back(t);
}

bool TextCursor::at_end() {
  const std::size_t pos = pos_;
  const long line = line_, token_line = token_line_;
  const bool line_start = at_line_start_;
  const bool end = next().empty();
  if (!end) {  // restore: at_end() only looks
    pos_ = pos;
    line_ = line;
    token_line_ = token_line;
    at_line_start_ = line_start;
  }
  return end;
}

void TextCursor::fail(const std::string& problem) const { detail::fail(file_, token_line_, problem); }

double TextCursor::to_double(std::string_view token, const char* what) const {
  std::string_view t = token;
  if (t.size() > 1 && t[0] == '+') t.remove_prefix(1);
  double value = 0.0;
  const auto [end, ec] = std::from_chars(t.data(), t.data() + t.size(), value);
  if (ec == std::errc::result_out_of_range)
    fail(fmt::format("number {} out of the range of double ({})", shown(token), what));
  if (ec != std::errc() || end != t.data() + t.size())
    fail(fmt::format("malformed number {} (expected {})", shown(token), what));
  if (!std::isfinite(value)) fail(fmt::format("non-finite value {} ({})", shown(token), what));
  return value;
}

long long TextCursor::to_int(std::string_view token, const char* what) const {
  std::string_view t = token;
  if (t.size() > 1 && t[0] == '+') t.remove_prefix(1);
  long long value = 0;
  const auto [end, ec] = std::from_chars(t.data(), t.data() + t.size(), value);
  if (ec == std::errc::result_out_of_range) fail(fmt::format("integer {} out of range ({})", shown(token), what));
  if (ec != std::errc() || end != t.data() + t.size())
    fail(fmt::format("malformed integer {} (expected {})", shown(token), what));
  return value;
}

std::string_view TextCursor::required(bool on_line, const char* what) {
  const std::string_view t = on_line ? next_on_line() : next();
  if (t.empty())
    fail(on_line ? fmt::format("missing {}", what) : fmt::format("unexpected end of file (expected {})", what));
  return t;
}

double TextCursor::read_double(const char* what) { return to_double(required(false, what), what); }
long long TextCursor::read_int(const char* what) { return to_int(required(false, what), what); }
double TextCursor::line_double(const char* what) { return to_double(required(true, what), what); }
long long TextCursor::line_int(const char* what) { return to_int(required(true, what), what); }

// ---- FaceList ----

void range_error(const std::string& file, long line, long long index, Index vertex_count, int index_base) {
  fail(file, line,
       fmt::format("vertex index {} out of range (the file has {} vertices, indices start at {})", index + index_base,
                   vertex_count, index_base));
}

void FaceList::add(const std::vector<int>& corners, const std::string& file, long line) {
  const std::size_t k = corners.size();
  if (k < 3) detail::fail(file, line, fmt::format("face with {} corner(s); at least 3 are needed", k));
  if (k > 3) ++polygons_;
  for (std::size_t i = 1; i + 1 < k; ++i) {
    const int tri[3] = {corners[0], corners[i], corners[i + 1]};
    triangles_.add(tri, line);
  }
}

Vertices vertex_matrix(const std::vector<double>& xyz) {
  return Eigen::Map<const Vertices>(xyz.data(), static_cast<Index>(xyz.size() / 3), 3);
}

void require_nonempty(const std::string& file, Index vertices, Index elements, const char* element_name) {
  if (vertices == 0) fail(file, 0, "no vertices (degenerate input)");
  if (elements == 0) fail(file, 0, fmt::format("no {} (degenerate input)", element_name));
}

void report(MeshReadInfo* info, const char* format, const FaceList& faces, const TriangleMesh& mesh) {
  if (info == nullptr) return;
  *info = MeshReadInfo{};
  info->format = format;
  info->polygons_triangulated = faces.polygons_triangulated();
  info->unreferenced_vertices = count_unreferenced(mesh.V.rows(), mesh.F);
  if (info->polygons_triangulated > 0)
    info->notes.push_back(fmt::format("{} polygon(s) with more than 3 corners fan-triangulated",
                                      info->polygons_triangulated));
  if (info->unreferenced_vertices > 0)
    info->notes.push_back(fmt::format("{} vertex(es) used by no face (kept)", info->unreferenced_vertices));
}

}  // namespace detail

}  // namespace qpreduce::deform
