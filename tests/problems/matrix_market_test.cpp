// Matrix Market reader/writer: exact round trips, and every malformed input
// rejected with the file and the line of the problem.
#include <qpreduce/problems/generators.h>
#include <qpreduce/problems/matrix_market.h>

#include <catch2/catch.hpp>

#include <filesystem>
#include <fstream>
#include <string>

using namespace qpreduce;
namespace fs = std::filesystem;

namespace {

fs::path temp_dir() {
  const fs::path dir = fs::temp_directory_path() / "qpreduce_mm_test";
  fs::create_directories(dir);
  return dir;
}

std::string write_text(const std::string& name, const std::string& text) {
  const std::string path = (temp_dir() / name).string();
  std::ofstream(path, std::ios::binary) << text;
  return path;
}

// Reads `text` (as a file) and checks the error names the file and `line`.
void require_rejected(const std::string& text, long line, const std::string& fragment,
                      const MarketReadOptions& options = {}) {
  const std::string path = write_text("bad.mtx", text);
  INFO(text);
  try {
    read_market_sparse(path, options);
    FAIL("accepted a malformed file");
  } catch (const MatrixMarketError& e) {
    CHECK(e.file() == path);
    CHECK(e.line() == line);
    CHECK_THAT(std::string(e.what()), Catch::Contains(path + ":" + std::to_string(line) + ":"));
    CHECK_THAT(e.problem(), Catch::Contains(fragment));
  }
}

const std::string kHeader = "%%MatrixMarket matrix coordinate real general\n";

}  // namespace

TEST_CASE("Matrix Market: sparse and dense round trips are exact", "[qp][io]") {
  const SparseMatrix<double> L = generators::grid_laplacian_2d(7, 5, 0.3);
  const SparseMatrix<double> G = generators::gaussian_sparse(35, 4, 11);
  const std::string pl = (temp_dir() / "L.mtx").string(), ps = (temp_dir() / "Ls.mtx").string(),
                    pg = (temp_dir() / "G.mtx").string(), pv = (temp_dir() / "v.mtx").string();
  write_market(pl, L);
  write_market(ps, L, /*symmetric=*/true);
  write_market(pg, G);
  const Vector<double> v = generators::gaussian_vector(35, 3);
  write_market(pv, Matrix<double>(v));
  MarketReadOptions sym;
  sym.require_symmetric = true;
  CHECK((read_market_sparse(pl, sym) - L).norm() == 0.0);
  CHECK((read_market_sparse(ps, sym) - L).norm() == 0.0);
  CHECK((read_market_sparse(pg) - G).norm() == 0.0);
  MarketReadOptions col;
  col.rows = 35;
  col.cols = 1;
  CHECK((read_market_dense(pv, col).col(0) - v).norm() == 0.0);
  // A coordinate file read densely, and pattern/integer fields.
  CHECK((read_market_dense(pg) - Matrix<double>(G)).norm() == 0.0);
  const std::string pat = write_text("pat.mtx", "%%MatrixMarket matrix coordinate pattern general\n% c\n3 2 2\n1 1\n\n3 2\n");
  const SparseMatrix<double> P = read_market_sparse(pat);
  CHECK(P.nonZeros() == 2);
  CHECK(P.coeff(2, 1) == 1.0);
  const std::string arr = write_text("arr.mtx", "%%MatrixMarket matrix array integer symmetric\n2 2\n4\n-1\n5\n");
  const Matrix<double> S = read_market_dense(arr);
  CHECK(S(0, 1) == -1.0);
  CHECK(S(1, 0) == -1.0);
  CHECK(S(1, 1) == 5.0);
}

TEST_CASE("Matrix Market: malformed files are rejected with file and line", "[qp][io]") {
  require_rejected("%%MatrixMarket matrix coordinate complex general\n1 1 1\n1 1 1 0\n", 1, "complex");
  require_rejected("hello\n", 1, "header");
  require_rejected("%%MatrixMarket matrix coordinate real hermitian\n", 1, "hermitian");
  require_rejected("", 1, "empty");
  require_rejected(kHeader + "% comment\n3 3\n", 3, "size line");
  require_rejected(kHeader + "3 3 2\n1 1 1.0\n2 2\n", 4, "expected 3 fields");
  require_rejected(kHeader + "3 3 2\n1 1 1.0\n4 2 1.0\n", 4, "row 4 out of range");
  require_rejected(kHeader + "3 3 2\n1 1 1.0\n2 0 1.0\n", 4, "col 0 out of range");
  require_rejected(kHeader + "3 3 2\n1 1 nan\n2 2 1.0\n", 3, "not finite");
  require_rejected(kHeader + "3 3 2\n1 1 1.0\n2 2 inf\n", 4, "not finite");
  require_rejected(kHeader + "3 3 2\n1 1 1.0\n2 2 x1\n", 4, "not a number");
  require_rejected(kHeader + "3 3 2\n1 1 1.0\n2 2 1.0abc\n", 4, "not a number");
  require_rejected(kHeader + "3 3 2\n1.5 1 1.0\n2 2 1.0\n", 3, "not an integer");
  require_rejected(kHeader + "3 3 3\n1 1 1.0\n2 2 1.0\n% end\n", 5, "file ends after 2");
  require_rejected(kHeader + "3 3 1\n1 1 1.0\n2 2 1.0\n", 4, "more entries");
  require_rejected(kHeader + "3 3 2\n2 1 1.0\n2 1 3.0\n", 4, "duplicate entry (2, 1) (first on line 3)");
  require_rejected("%%MatrixMarket matrix coordinate real symmetric\n3 3 1\n1 2 1.0\n", 3, "above the diagonal");
  require_rejected("%%MatrixMarket matrix array real general\n2 1\n1.0\n", 3, "file ends after 1");

  MarketReadOptions rows;
  rows.rows = 4;
  require_rejected(kHeader + "% c\n3 3 1\n1 1 1.0\n", 3, "expected 4 rows, got 3", rows);

  MarketReadOptions sym;
  sym.require_symmetric = true;
  require_rejected(kHeader + "2 2 3\n1 1 2.0\n2 1 -1.0\n1 2 -1.5\n", 4, "not symmetric", sym);
  require_rejected(kHeader + "2 2 2\n1 1 2.0\n2 1 -1.0\n", 4, "no mirror entry", sym);
  require_rejected(kHeader + "2 3 0\n", 2, "square", sym);

  SECTION("a missing file names the file") {
    try {
      read_market_sparse((temp_dir() / "does_not_exist.mtx").string());
      FAIL("opened a missing file");
    } catch (const MatrixMarketError& e) {
      CHECK(e.line() == 0);
      CHECK_THAT(std::string(e.what()), Catch::Contains("does_not_exist.mtx"));
    }
  }
}

TEST_CASE("Matrix Market: a range of rows is those rows of the whole matrix", "[qp][io][rows]") {
  const SparseMatrix<double> L = generators::grid_laplacian_2d(7, 5, 0.3);  // 35 × 35, symmetric
  const SparseMatrix<double> G = generators::gaussian_sparse(35, 4, 11);
  const std::string pl = (temp_dir() / "Lr.mtx").string(), ps = (temp_dir() / "Lsr.mtx").string(),
                    pg = (temp_dir() / "Gr.mtx").string();
  write_market(pl, L);                      // general storage
  write_market(ps, L, /*symmetric=*/true);  // lower triangle only
  write_market(pg, G);
  MarketReadOptions sym;
  sym.require_symmetric = true;
  CHECK(read_market_size(pl, sym) == std::pair<Index, Index>{35, 35});
  CHECK(read_market_size(pg) == std::pair<Index, Index>{35, 4});
  // Three blocks tiling the rows, one of them empty, as ranks would own them.
  for (const auto& [first, end] : {std::pair<Index, Index>{0, 12}, {12, 12}, {12, 35}}) {
    INFO("rows [" << first << ", " << end << ")");
    for (const std::string& path : {pl, ps}) {
      const SparseMatrix<double> rows = read_market_sparse_rows(path, first, end, sym);
      REQUIRE(rows.rows() == end - first);
      REQUIRE(rows.cols() == 35);
      CHECK(SparseMatrix<double>(rows - SparseMatrix<double>(L.middleRows(first, end - first))).norm() == 0.0);
    }
    const SparseMatrix<double> g = read_market_sparse_rows(pg, first, end);
    CHECK(SparseMatrix<double>(g - SparseMatrix<double>(G.middleRows(first, end - first))).norm() == 0.0);
  }
  CHECK_THROWS_WITH(read_market_sparse_rows(pl, 30, 36), Catch::Contains("outside the matrix's 35 rows"));
  CHECK_THROWS_AS(read_market_sparse_rows(pl, 5, 4), std::invalid_argument);

  // An asymmetric pair across two blocks: the reader of either block sees it
  // (it keeps the mirrors of its columns), with the whole file's tolerance.
  const std::string asym = write_text("asym.mtx", kHeader + "4 4 4\n1 1 2\n4 1 1\n1 4 1.5\n4 4 2\n");
  for (const auto& [first, end] : {std::pair<Index, Index>{0, 2}, {2, 4}}) {
    try {
      read_market_sparse_rows(asym, first, end, sym);
      if (first == 0) FAIL("rows [0, 2) hold (1, 4) = 1.5 against (4, 1) = 1 and were accepted");
    } catch (const MatrixMarketError& e) {
      CHECK_THAT(e.problem(), Catch::Contains("not symmetric"));
    }
  }
  // A malformed line outside the kept rows still fails the read.
  const std::string broken = write_text("broken_rows.mtx", kHeader + "4 4 2\n1 1 2\n4 4 x\n");
  try {
    read_market_sparse_rows(broken, 0, 2);
    FAIL("a malformed entry in another block's rows was accepted");
  } catch (const MatrixMarketError& e) {
    CHECK(e.line() == 4);
  }
}
