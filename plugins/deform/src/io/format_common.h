// Internal to qpreduce_deform: the pieces every reader and writer shares —
// whole-file input, a text cursor with line numbers and strict number
// parsing, polygon triangulation, and buffered output.
#pragma once

#include "qpreduce/deform/io/io_error.h"
#include "qpreduce/deform/mesh/mesh.h"
#include "qpreduce/deform/io/mesh_io.h"

#include <fmt/format.h>

#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace qpreduce::deform::detail {

// The whole file; IoError "<path>: cannot open file (<reason>)" when missing.
std::string read_file(const std::string& path);
// Writes `bytes` to `path` through a temporary file renamed on success
// (qpreduce::AtomicFile); IoError when the file cannot be written, the
// earlier file then untouched.
void write_file(const std::string& path, std::string_view bytes);
// A set of files that belong together, all or none up to the renames
// (qpreduce::write_files_atomically); IoError as write_file.
void write_files(const std::vector<std::pair<std::string, std::string_view>>& files);
// ".obj" for "dir/Mesh.OBJ"; "" without an extension.
std::string lower_extension(const std::string& path);
// `path` without its extension ("dir/a.node" → "dir/a").
std::string strip_extension(const std::string& path);
bool file_exists(const std::string& path);

[[noreturn]] void fail(const std::string& file, long line, const std::string& problem);
// `token` quoted for a message: bytes outside printable ASCII as \xHH, cut
// after 40 bytes with its length ("'\xEF\xBB\xBFOFF'", "'aaaa…' (1048576 bytes)").
std::string shown(std::string_view token);

// Reads whitespace-separated tokens from `text`, counting lines. The comment
// character (none if '\0') hides the rest of its line. Two ways to use it:
//   * as a token stream, ignoring lines:  next(), read_double(), read_int();
//   * line by line: begin_line() moves to the next line with a token, then
//     next_on_line() / line_double() / line_int() / split_line() read it.
class TextCursor {
 public:
  TextCursor(std::string file, std::string_view text, long first_line = 1, char comment = '#');

  // Next token anywhere; empty at the end of the text.
  std::string_view next();
  // Moves past the current line to the next one that has a token; false at
  // the end of the text.
  bool begin_line();
  // Next token of the current line; empty at the end of the line.
  std::string_view next_on_line();
  // The remaining tokens of the current line.
  void split_line(std::vector<std::string_view>& tokens);
  // True when no token is left.
  bool at_end();

  double read_double(const char* what);  // next(), or "unexpected end of file"
  long long read_int(const char* what);
  double line_double(const char* what);  // next_on_line(), or "missing <what>"
  long long line_int(const char* what);

  double to_double(std::string_view token, const char* what) const;
  long long to_int(std::string_view token, const char* what) const;

  // Line of the last token read, so an "unexpected end of file" names the
  // last line that has data.
  long line() const { return token_line_; }
  const std::string& file() const { return file_; }
  [[noreturn]] void fail(const std::string& problem) const;
  // Byte offset in `text` just past the last token.
  std::size_t offset() const { return pos_; }

 private:
  void skip_blanks_on_line();  // spaces, tabs, '\r', and a comment
  // The next token (of the line, or anywhere); fails when there is none.
  std::string_view required(bool on_line, const char* what);
  std::string_view take_token();

  std::string file_;
  std::string_view text_;
  std::size_t pos_ = 0;
  long line_;
  long token_line_;
  char comment_;
  bool at_line_start_ = true;
};

// "vertex index <index + base> out of range (the file has N vertices, indices start at <base>)".
[[noreturn]] void range_error(const std::string& file, long line, long long index, Index vertex_count,
                              int index_base);

// Rows of K vertex indices with the line each came from, so that index
// range errors found after the whole file is read still name their line.
template <int K>
class ElementList {
 public:
  void add(const int* corners, long line) {
    index_.insert(index_.end(), corners, corners + K);
    line_.push_back(line);
  }
  // Checks every index against [0, vertex_count); the message prints the
  // index with `index_base` added (as the file wrote it).
  void check_range(const std::string& file, Index vertex_count, int index_base) const {
    for (std::size_t i = 0; i < index_.size(); ++i)
      if (index_[i] < 0 || index_[i] >= vertex_count) range_error(file, line_[i / K], index_[i], vertex_count, index_base);
  }
  Eigen::Matrix<int, Eigen::Dynamic, K, Eigen::RowMajor> matrix() const {
    return Eigen::Map<const Eigen::Matrix<int, Eigen::Dynamic, K, Eigen::RowMajor>>(index_.data(), rows(), K);
  }
  Index rows() const { return static_cast<Index>(line_.size()); }

 private:
  std::vector<int> index_;
  std::vector<long> line_;
};

// Triangles of polygons, fan-triangulated (see mesh_io.h).
class FaceList {
 public:
  // Adds polygon `corners` (≥ 3, else an error at `line`).
  void add(const std::vector<int>& corners, const std::string& file, long line);
  void add(const std::vector<int>& corners, const TextCursor& at) { add(corners, at.file(), at.line()); }
  void check_range(const std::string& file, Index vertex_count, int index_base) const {
    triangles_.check_range(file, vertex_count, index_base);
  }
  Triangles matrix() const { return triangles_.matrix(); }
  Index triangles() const { return triangles_.rows(); }
  Index polygons_triangulated() const { return polygons_; }

 private:
  ElementList<3> triangles_;
  Index polygons_ = 0;
};

Vertices vertex_matrix(const std::vector<double>& xyz);
// Vertices that none of the rows of `elements` uses.
template <typename Elements>
Index count_unreferenced(Index vertex_count, const Elements& elements) {
  std::vector<char> used(static_cast<std::size_t>(vertex_count), 0);
  for (Index i = 0; i < elements.size(); ++i) used[static_cast<std::size_t>(elements.data()[i])] = 1;
  Index unused = 0;
  for (char u : used) unused += u ? 0 : 1;
  return unused;
}
// Throws "<file>: no vertices" / "no faces" for empty meshes (degenerate input).
void require_nonempty(const std::string& file, Index vertices, Index elements, const char* element_name);
// Fills `info` (when non-null) for a surface read.
void report(MeshReadInfo* info, const char* format, const FaceList& faces, const TriangleMesh& mesh);

// A reservation that trusts a header count only as far as the file is long.
inline std::size_t capped(long long count, std::size_t per_item, std::size_t file_size) {
  if (count <= 0) return 0;
  const std::size_t bound = file_size / (per_item > 0 ? per_item : 1) + 1;
  return static_cast<std::size_t>(count) < bound ? static_cast<std::size_t>(count) : bound;
}

// Buffered text output; doubles print in their shortest round-trip form.
using Buffer = fmt::memory_buffer;
inline void put_xyz(Buffer& out, const char* prefix, const Vertices& V, Index i, const char* suffix) {
  fmt::format_to(std::back_inserter(out), "{}{} {} {}{}\n", prefix, V(i, 0), V(i, 1), V(i, 2), suffix);
}
template <typename Rows>
void put_rows(Buffer& out, const char* prefix, const Rows& rows, int offset, const char* suffix) {
  for (Index i = 0; i < rows.rows(); ++i) {
    fmt::format_to(std::back_inserter(out), "{}", prefix);
    for (Index j = 0; j < rows.cols(); ++j)
      fmt::format_to(std::back_inserter(out), "{}{}", j == 0 ? "" : " ", rows(i, j) + offset);
    fmt::format_to(std::back_inserter(out), "{}\n", suffix);
  }
}
inline void write_buffer(const std::string& path, const Buffer& out) {
  write_file(path, std::string_view(out.data(), out.size()));
}

}  // namespace qpreduce::deform::detail
