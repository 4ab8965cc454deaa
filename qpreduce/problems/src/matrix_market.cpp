#include "qpreduce/problems/matrix_market.h"

#include "qpreduce/util/atomic_file.h"

#include <fmt/format.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <vector>

namespace qpreduce {

bool MarketReadOptions::is_valid(std::string* why) const {
  auto fail = [&](const std::string& s) {
    if (why) *why = s;
    return false;
  };
  if (rows < -1 || cols < -1) return fail(fmt::format("rows/cols must be ≥ −1, got {}, {}", rows, cols));
  if (!(symmetry_tolerance >= 0.0) || !std::isfinite(symmetry_tolerance)) {
    return fail(fmt::format("symmetry_tolerance must be finite and ≥ 0, got {}", symmetry_tolerance));
  }
  return true;
}

namespace {

struct Entry {
  Index row, col;
  double value;
  long line;
};

enum class Field { Real, Integer, Pattern };
enum class Symmetry { General, Symmetric };

// What a header may declare against the size of its file, so that no
// allocation exceeds a small multiple of what the file can hold: a value of
// array storage takes at least 2 bytes ("0\n"), an entry of coordinate
// storage at least 4 ("1 1\n"); a dimension costs memory even when its rows
// or columns are empty, so rows and columns may each be at most
// kDimensionsPerByte per byte of the file or kFreeDimension, whichever is
// larger — unless the caller's options expect that very size.
constexpr Index kMinValueBytes = 2;
constexpr Index kMinEntryBytes = 4;
constexpr Index kDimensionsPerByte = 16;
constexpr Index kFreeDimension = Index(1) << 22;

Index dimension_limit(Index file_bytes) { return std::max(kFreeDimension, kDimensionsPerByte * file_bytes); }

// Rows [first, end) of the matrix to keep (end < 0: all of them).
struct RowFilter {
  Index first = 0, end = -1;
  bool all() const { return end < 0; }
  bool has(Index i) const { return all() || (i >= first && i < end); }
};

struct Parsed {
  Index rows = 0, cols = 0;
  Index file_bytes = 0;
  Symmetry symmetry = Symmetry::General;
  long size_line = 0;
  std::vector<Entry> entries;  // 0-based, as stored (one triangle for symmetric); see keep()
  double max_abs = 0.0;        // over every value read, kept or not
  RowFilter filter;
  bool mirrors = false;  // keep the entries of the filter's columns too (symmetric storage, symmetry check)
  // Whether entry (i, j) is kept: in a row of the filter, or with mirrors
  // in one of its columns (it then gives row j by symmetry, or is the
  // mirror a kept entry is checked against).
  bool keep(Index i, Index j) const { return filter.has(i) || (mirrors && filter.has(j)); }
};

std::string lower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

std::vector<std::string> split(const std::string& line) {
  std::istringstream in(line);
  std::vector<std::string> out;
  for (std::string t; in >> t;) out.push_back(t);
  return out;
}

bool blank(const std::string& line) {
  return std::all_of(line.begin(), line.end(), [](char c) { return std::isspace(static_cast<unsigned char>(c)); });
}

class LineReader {
 public:
  explicit LineReader(const std::string& path) : path_(path), in_(path) {
    if (!in_) throw MatrixMarketError(path, 0, "cannot open file");
  }
  // Next line that is neither blank nor a comment; false at end of file.
  bool next_data(std::string* line) {
    while (std::getline(in_, *line)) {
      ++line_;
      if (!line->empty() && line->back() == '\r') line->pop_back();
      if (blank(*line) || (*line)[line->find_first_not_of(" \t")] == '%') continue;
      return true;
    }
    return false;
  }
  bool next_raw(std::string* line) {
    if (!std::getline(in_, *line)) return false;
    ++line_;
    if (!line->empty() && line->back() == '\r') line->pop_back();
    return true;
  }
  [[noreturn]] void fail(const std::string& problem) const { throw MatrixMarketError(path_, line_, problem); }
  long line() const { return line_; }

 private:
  std::string path_;
  std::ifstream in_;
  long line_ = 0;
};

Index parse_index(LineReader& r, const std::string& token, const char* what) {
  errno = 0;
  char* end = nullptr;
  const long long v = std::strtoll(token.c_str(), &end, 10);
  if (end == token.c_str() || *end != '\0' || errno == ERANGE) r.fail(fmt::format("{} '{}' is not an integer", what, token));
  return static_cast<Index>(v);
}

double parse_value(LineReader& r, const std::string& token, Field field) {
  if (field == Field::Integer) return static_cast<double>(parse_index(r, token, "value"));
  errno = 0;
  char* end = nullptr;
  const double v = std::strtod(token.c_str(), &end);
  if (end == token.c_str() || *end != '\0') r.fail(fmt::format("value '{}' is not a number", token));
  if (!std::isfinite(v)) r.fail(fmt::format("value '{}' is not finite", token));
  return v;
}

struct Header {
  bool array = false;  // "array" (dense, column-major) rather than "coordinate"
  Field field = Field::Real;
  Symmetry symmetry = Symmetry::General;
};

// Reads and checks the "%%MatrixMarket matrix <format> <field> <symmetry>" line.
Header read_header(LineReader& r, const std::string& path) {
  std::string line;
  if (!r.next_raw(&line)) throw MatrixMarketError(path, 1, "empty file (expected a '%%MatrixMarket' header)");
  const std::vector<std::string> h = split(line);
  if (h.empty() || lower(h[0]) != "%%matrixmarket") r.fail("expected a '%%MatrixMarket matrix ...' header");
  if (h.size() != 5) {
    r.fail(fmt::format("header: expected 5 words (%%MatrixMarket matrix <format> <field> <symmetry>), got {}",
                       h.size()));
  }
  if (lower(h[1]) != "matrix") r.fail(fmt::format("header: object '{}' is not supported (expected 'matrix')", h[1]));
  const std::string format = lower(h[2]), field_s = lower(h[3]), sym_s = lower(h[4]);
  if (format != "coordinate" && format != "array") {
    r.fail(fmt::format("header: format '{}' is not supported (expected coordinate or array)", h[2]));
  }
  Header header;
  if (field_s == "integer") header.field = Field::Integer;
  else if (field_s == "pattern") header.field = Field::Pattern;
  else if (field_s != "real" && field_s != "double") {
    r.fail(fmt::format("header: field '{}' is not supported (expected real, integer or pattern)", h[3]));
  }
  if (sym_s == "symmetric") header.symmetry = Symmetry::Symmetric;
  else if (sym_s != "general") {
    r.fail(fmt::format("header: symmetry '{}' is not supported (expected general or symmetric)", h[4]));
  }
  header.array = format == "array";
  if (header.array && header.field == Field::Pattern) r.fail("header: array storage cannot be 'pattern'");
  return header;
}

// Rejects sizes the file cannot back (see kMinValueBytes): before anything is
// reserved, so that a forged header fails at once instead of exhausting memory.
void check_declared_sizes(LineReader& r, const MarketReadOptions& options, Index declared, bool array,
                          const Parsed& p) {
  const Index limit = dimension_limit(p.file_bytes);
  if (options.rows < 0 && p.rows > limit)
    r.fail(fmt::format("size line: {} rows is more than a file of {} bytes can describe (at most {})", p.rows,
                       p.file_bytes, limit));
  if (options.cols < 0 && p.cols > limit)
    r.fail(fmt::format("size line: {} columns is more than a file of {} bytes can describe (at most {})", p.cols,
                       p.file_bytes, limit));
  const Index most_entries = p.file_bytes / (array ? kMinValueBytes : kMinEntryBytes);
  if (array) {
    // rows·cols without overflow: compare rows against most_entries / cols.
    const bool sym = p.symmetry == Symmetry::Symmetric;
    const Index cols = sym ? (p.cols + 1) / 2 : p.cols;
    if (cols > 0 && p.rows > most_entries / cols)
      r.fail(fmt::format("size line: {} × {} values cannot fit in a file of {} bytes", p.rows, p.cols, p.file_bytes));
  } else if (declared > most_entries) {
    r.fail(fmt::format("size line: {} entries cannot fit in a file of {} bytes (at most {})", declared, p.file_bytes,
                       most_entries));
  }
}

// Reads the size line into p (rows, cols, size_line), checks it against the
// header and the options, and returns the declared entry count (0 for array).
Index read_size_line(LineReader& r, const Header& header, const MarketReadOptions& options, Parsed& p) {
  std::string line;
  const bool array = header.array;
  if (!r.next_data(&line)) r.fail("missing size line");
  p.size_line = r.line();
  const std::vector<std::string> s = split(line);
  const size_t size_fields = array ? 2 : 3;
  if (s.size() != size_fields) {
    r.fail(fmt::format("size line: expected {} integers ({}), got {} fields", size_fields,
                       array ? "rows cols" : "rows cols entries", s.size()));
  }
  p.rows = parse_index(r, s[0], "rows");
  p.cols = parse_index(r, s[1], "cols");
  const Index declared = array ? 0 : parse_index(r, s[2], "entries");
  if (p.rows < 0 || p.cols < 0 || declared < 0) r.fail("size line: negative size");
  if (options.rows >= 0 && p.rows != options.rows) {
    r.fail(fmt::format("expected {} rows, got {}", options.rows, p.rows));
  }
  if (options.cols >= 0 && p.cols != options.cols) {
    r.fail(fmt::format("expected {} columns, got {}", options.cols, p.cols));
  }
  check_declared_sizes(r, options, declared, array, p);
  if (p.symmetry == Symmetry::Symmetric && p.rows != p.cols) {
    r.fail(fmt::format("symmetric storage needs a square matrix, got {} × {}", p.rows, p.cols));
  }
  if (options.require_symmetric && p.rows != p.cols) {
    r.fail(fmt::format("expected a square (symmetric) matrix, got {} × {}", p.rows, p.cols));
  }
  return declared;
}

// Array storage: one value per line, column-major; symmetric storage lists
// the lower triangle only. Zeros are not stored.
void read_array_values(LineReader& r, Field field, Parsed& p) {
  std::string line;
  const bool sym = p.symmetry == Symmetry::Symmetric;
  Index i = 0, j = 0;
  const Index total = sym ? p.rows * (p.rows + 1) / 2 : p.rows * p.cols;
  if (p.filter.all()) p.entries.reserve(static_cast<size_t>(total));
  for (Index e = 0; e < total; ++e) {
    if (!r.next_data(&line)) r.fail(fmt::format("expected {} values, the file ends after {}", total, e));
    const std::vector<std::string> t = split(line);
    if (t.size() != 1) r.fail(fmt::format("expected 1 value per line (array storage), got {} fields", t.size()));
    const double v = parse_value(r, t[0], field);
    p.max_abs = std::max(p.max_abs, std::abs(v));
    if (v != 0.0 && p.keep(i, j)) p.entries.push_back({i, j, v, r.line()});
    if (++i == p.rows) {
      ++j;
      i = sym ? j : 0;
    }
  }
}

// Coordinate storage: `declared` lines "row col [value]", 1-based.
void read_coordinate_entries(LineReader& r, Field field, Index declared, Parsed& p) {
  std::string line;
  const bool sym = p.symmetry == Symmetry::Symmetric;
  if (p.filter.all()) p.entries.reserve(static_cast<size_t>(declared));
  const size_t fields = field == Field::Pattern ? 2 : 3;
  for (Index e = 0; e < declared; ++e) {
    if (!r.next_data(&line)) r.fail(fmt::format("expected {} entries, the file ends after {}", declared, e));
    const std::vector<std::string> t = split(line);
    if (t.size() != fields) {
      r.fail(fmt::format("expected {} fields ({}), got {}", fields, fields == 2 ? "row col" : "row col value",
                         t.size()));
    }
    const Index i = parse_index(r, t[0], "row"), j = parse_index(r, t[1], "col");
    if (i < 1 || i > p.rows) r.fail(fmt::format("row {} out of range [1, {}]", i, p.rows));
    if (j < 1 || j > p.cols) r.fail(fmt::format("col {} out of range [1, {}]", j, p.cols));
    if (sym && i < j) r.fail(fmt::format("entry ({}, {}) above the diagonal in symmetric storage", i, j));
    const double v = field == Field::Pattern ? 1.0 : parse_value(r, t[2], field);
    p.max_abs = std::max(p.max_abs, std::abs(v));
    if (p.keep(i - 1, j - 1)) p.entries.push_back({i - 1, j - 1, v, r.line()});
  }
}

// Sorts the entries by (col, row) and rejects two entries at one position.
void sort_and_reject_duplicates(const std::string& path, std::vector<Entry>& entries) {
  std::stable_sort(entries.begin(), entries.end(),
                   [](const Entry& a, const Entry& b) { return a.col != b.col ? a.col < b.col : a.row < b.row; });
  for (size_t e = 1; e < entries.size(); ++e) {
    const Entry &a = entries[e - 1], &b = entries[e];
    if (a.row == b.row && a.col == b.col) {
      throw MatrixMarketError(path, b.line,
                              fmt::format("duplicate entry ({}, {}) (first on line {})", b.row + 1, b.col + 1, a.line));
    }
  }
}

// General storage checked for symmetry: |a_ij − a_ji| ≤ tolerance · max|a|.
// Precondition: entries sorted by (col, row).
// max_abs: over every value of the file (not only the kept entries, whose
// mirrors are kept with them).
void check_symmetric(const std::string& path, const std::vector<Entry>& entries, double symmetry_tolerance,
                     double max_abs) {
  const double tol = symmetry_tolerance * max_abs;
  auto find = [&](Index row, Index col) -> const Entry* {
    const auto it = std::lower_bound(entries.begin(), entries.end(), std::make_pair(col, row),
                                     [](const Entry& a, const std::pair<Index, Index>& key) {
                                       return a.col != key.first ? a.col < key.first : a.row < key.second;
                                     });
    return it != entries.end() && it->row == row && it->col == col ? &*it : nullptr;
  };
  for (const Entry& e : entries) {
    if (e.row == e.col) continue;
    const Entry* mirror = find(e.col, e.row);
    const double m = mirror ? mirror->value : 0.0;
    if (std::abs(e.value - m) > tol) {
      throw MatrixMarketError(
          path, e.line,
          mirror ? fmt::format("not symmetric: entry ({}, {}) = {} but ({}, {}) = {} (line {})", e.row + 1, e.col + 1,
                               e.value, e.col + 1, e.row + 1, m, mirror->line)
                 : fmt::format("not symmetric: entry ({}, {}) = {} has no mirror entry ({}, {})", e.row + 1,
                               e.col + 1, e.value, e.col + 1, e.row + 1));
    }
  }
}

// The header and the size line of the file `r` reads, into *p (rows, cols,
// symmetry, the file's size); returns the header and the declared entries.
// (Precondition: options.is_valid, checked by check_read_options before the
// file is opened.)
std::pair<Header, Index> read_preamble(LineReader& r, const std::string& path, const MarketReadOptions& options,
                                       Parsed* p) {
  const Header header = read_header(r, path);
  p->symmetry = header.symmetry;
  std::error_code ec;
  p->file_bytes = static_cast<Index>(std::filesystem::file_size(path, ec));
  if (ec) p->file_bytes = 0;
  const Index declared = read_size_line(r, header, options, *p);
  return {header, declared};
}

void check_read_options(const MarketReadOptions& options) {
  std::string why;
  if (!options.is_valid(&why)) throw std::invalid_argument("MarketReadOptions: " + why);
}

Parsed parse(const std::string& path, const MarketReadOptions& options, RowFilter filter = {}) {
  check_read_options(options);
  LineReader r(path);
  Parsed p;
  const auto [header, declared] = read_preamble(r, path, options, &p);
  p.filter = filter;
  p.mirrors = header.symmetry == Symmetry::Symmetric || options.require_symmetric;
  if (!filter.all() && (filter.first < 0 || filter.first > filter.end || filter.end > p.rows)) {
    throw std::invalid_argument(fmt::format("{}: rows [{}, {}) outside the matrix's {} rows", path, filter.first,
                                            filter.end, p.rows));
  }
  if (header.array) read_array_values(r, header.field, p);
  else read_coordinate_entries(r, header.field, declared, p);
  std::string line;
  if (r.next_data(&line)) {
    r.fail(header.array ? "more values than rows × cols" : fmt::format("more entries than the {} declared", declared));
  }
  sort_and_reject_duplicates(path, p.entries);
  if (options.require_symmetric && p.symmetry != Symmetry::Symmetric) {
    check_symmetric(path, p.entries, options.symmetry_tolerance, p.max_abs);
  }
  return p;
}

}  // namespace

namespace {
// The kept rows [first, first + count) of a parsed file, symmetric storage
// expanded.
SparseMatrix<double> sparse_rows(const Parsed& p, Index first, Index count) {
  std::vector<Eigen::Triplet<double>> t;
  t.reserve(p.entries.size() * (p.symmetry == Symmetry::Symmetric ? 2 : 1));
  const auto put = [&](Index i, Index j, double v) {
    if (i >= first && i < first + count) t.emplace_back(i - first, j, v);
  };
  for (const Entry& e : p.entries) {
    put(e.row, e.col, e.value);
    if (p.symmetry == Symmetry::Symmetric && e.row != e.col) put(e.col, e.row, e.value);
  }
  SparseMatrix<double> M(count, p.cols);
  M.setFromTriplets(t.begin(), t.end());
  return M;
}
}  // namespace

std::pair<Index, Index> read_market_size(const std::string& path, const MarketReadOptions& options) {
  check_read_options(options);
  LineReader r(path);
  Parsed p;
  read_preamble(r, path, options, &p);
  return {p.rows, p.cols};
}

SparseMatrix<double> read_market_sparse(const std::string& path, const MarketReadOptions& options) {
  const Parsed p = parse(path, options);
  return sparse_rows(p, 0, p.rows);
}

SparseMatrix<double> read_market_sparse_rows(const std::string& path, Index first, Index end,
                                             const MarketReadOptions& options) {
  if (first < 0 || end < first) {
    throw std::invalid_argument(fmt::format("read_market_sparse_rows: rows [{}, {}) is not a range", first, end));
  }
  const Parsed p = parse(path, options, RowFilter{first, end});
  return sparse_rows(p, first, end - first);
}

Matrix<double> read_market_dense(const std::string& path, const MarketReadOptions& options) {
  const Parsed p = parse(path, options);
  // Coordinate storage read densely: rows·cols doubles however few entries
  // the file holds, so the product is bounded too unless both were expected.
  const Index limit = dimension_limit(p.file_bytes);
  if ((options.rows < 0 || options.cols < 0) && p.cols > 0 && p.rows > limit / p.cols) {
    throw MatrixMarketError(path, p.size_line,
                            fmt::format("a dense {} × {} matrix is more than a file of {} bytes can describe "
                                        "(rows × columns at most {})",
                                        p.rows, p.cols, p.file_bytes, limit));
  }
  Matrix<double> M = Matrix<double>::Zero(p.rows, p.cols);
  for (const Entry& e : p.entries) {
    M(e.row, e.col) = e.value;
    if (p.symmetry == Symmetry::Symmetric) M(e.col, e.row) = e.value;
  }
  return M;
}

namespace {
// Writes what `fill` puts in the buffer through an AtomicFile, a chunk at a
// time; failures as MatrixMarketError, the earlier file untouched.
template <typename Fill>
void write_through(const std::string& path, const Fill& fill) {
  try {
    AtomicFile file(path);
    fmt::memory_buffer out;
    const auto drain = [&] {
      file.write(out.data(), out.size());
      out.clear();
    };
    fill(out, drain);
    drain();
    file.commit();
  } catch (const FileError& e) {
    throw MatrixMarketError(path, 0, e.problem());
  }
}
// Bytes gathered before they are handed to the file.
constexpr std::size_t kChunkBytes = std::size_t(1) << 16;
}  // namespace

void write_market(const std::string& path, const SparseMatrix<double>& M, bool symmetric) {
  write_through(path, [&](fmt::memory_buffer& out, const auto& drain) {
    Index count = 0;
    for (Index j = 0; j < M.outerSize(); ++j)
      for (SparseMatrix<double>::InnerIterator it(M, j); it; ++it) count += !symmetric || it.row() >= it.col();
    fmt::format_to(std::back_inserter(out), "%%MatrixMarket matrix coordinate real {}\n{} {} {}\n",
                   symmetric ? "symmetric" : "general", M.rows(), M.cols(), count);
    for (Index j = 0; j < M.outerSize(); ++j)
      for (SparseMatrix<double>::InnerIterator it(M, j); it; ++it) {
        if (symmetric && it.row() < it.col()) continue;
        fmt::format_to(std::back_inserter(out), "{} {} {:.17g}\n", it.row() + 1, it.col() + 1, it.value());
        if (out.size() > kChunkBytes) drain();
      }
  });
}

void write_market(const std::string& path, const Matrix<double>& M) {
  write_through(path, [&](fmt::memory_buffer& out, const auto& drain) {
    fmt::format_to(std::back_inserter(out), "%%MatrixMarket matrix array real general\n{} {}\n", M.rows(), M.cols());
    for (Index j = 0; j < M.cols(); ++j)
      for (Index i = 0; i < M.rows(); ++i) {
        fmt::format_to(std::back_inserter(out), "{:.17g}\n", M(i, j));
        if (out.size() > kChunkBytes) drain();
      }
  });
}

}  // namespace qpreduce
