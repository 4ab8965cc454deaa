// qpreduce — a strict Matrix Market reader and writer for QP data (H, C, D,
// demands). Format: https://math.nist.gov/MatrixMarket/formats.html
//
//   %%MatrixMarket matrix coordinate real general      (or: integer, pattern;
//   % comments                                           symmetric; array)
//   rows cols nnz                                        (array: rows cols)
//   i j value                                            1-based, one per line
//
// Unlike Eigen's unsupported loadMarket, every problem is reported with the
// file and line it was found on (MatrixMarketError): a malformed header or
// size line, a wrong field count, an index out of range, a non-numeric, NaN
// or infinite value, a duplicate entry, an upper-triangle entry in symmetric
// storage, too few or too many entries, wrong dimensions (the size line), and
// — when asked — an entry of a general-storage matrix whose mirror differs
// (H must be symmetric, Eq. 1). Complex, Hermitian and skew-symmetric files
// are rejected by name. Blank lines are skipped; comment lines ('%') may
// appear anywhere after the header.
#pragma once

#include "qpreduce/common.h"
#include "qpreduce/util/file_error.h"

#include <stdexcept>
#include <string>
#include <utility>

namespace qpreduce {

// Thrown on any problem with a Matrix Market file. line = 0 when the problem
// is not tied to one line (cannot open the file). what() is
// "<file>:<line>: <problem>" (or "<file>: <problem>"); see FileError.
class MatrixMarketError : public FileError {
 public:
  MatrixMarketError(std::string file, long line, std::string problem)
      : FileError(std::move(file), line, std::move(problem)) {}
};

struct MarketReadOptions {
  // Expected dimensions, checked against the size line; −1 accepts any.
  Index rows = -1, cols = -1;
  // Require a square matrix equal to its transpose. Symmetric storage is
  // symmetric by construction; general storage is checked entry by entry:
  // |a_ij − a_ji| ≤ symmetry_tolerance·max|a| (a missing mirror counts as 0).
  bool require_symmetric = false;
  // Relative entry-wise tolerance of the symmetry check. Values written with
  // 17 significant digits (write_market) round-trip exactly; 1e-12 leaves
  // room for a writer that printed 15.
  double symmetry_tolerance = 1e-12;

  bool is_valid(std::string* why) const;
};

// Reads a real matrix (coordinate or array storage) into a sparse matrix;
// symmetric storage is expanded to both triangles. Throws MatrixMarketError
// (file and line) on any problem listed above, std::invalid_argument on
// invalid options.
SparseMatrix<double> read_market_sparse(const std::string& path, const MarketReadOptions& options = {});
// (rows, cols) from the header and the size line alone, checked as the
// readers check them (a process that reads only some rows learns n first).
std::pair<Index, Index> read_market_size(const std::string& path, const MarketReadOptions& options = {});
// Rows [first, end) only ((end − first) × cols), for a process that owns
// those rows of a distributed build: the whole file is read and checked as
// above (a broken file fails on every reader), but only the entries of
// these rows are kept — with symmetric storage or require_symmetric, also
// those of these columns, for the mirrors, so the symmetry check covers
// every kept entry (tolerance relative to the whole file's max|a|).
// Throws std::invalid_argument when [first, end) is not within the rows.
SparseMatrix<double> read_market_sparse_rows(const std::string& path, Index first, Index end,
                                             const MarketReadOptions& options = {});
// The same into a dense matrix (vectors: rows × 1, usually array storage).
Matrix<double> read_market_dense(const std::string& path, const MarketReadOptions& options = {});

// Writers: coordinate real general (sparse; symmetric=true stores the lower
// triangle of a matrix the caller guarantees symmetric) and array real
// general (dense), 17 significant digits so that values round-trip exactly.
// Throw MatrixMarketError (line 0) when the file cannot be written; they write
// through a temporary file renamed on success (AtomicFile), so a failure leaves
// the earlier file untouched.
void write_market(const std::string& path, const SparseMatrix<double>& M, bool symmetric = false);
void write_market(const std::string& path, const Matrix<double>& M);

}  // namespace qpreduce
