// `qpr qp`'s demands (cmd_qp.cpp): the files of each demand (A or A_c, b,
// q or Y) from a directory or a JSON manifest, and the demand read from them.
// The formats: the header of cmd_qp.cpp and docs/examples/qp_files.md.
#pragma once

#include <qpreduce/common.h>

#include <filesystem>
#include <string>
#include <vector>

namespace qpr {

struct DemandFiles {
  std::string name, A, Ac, b, q, Y;  // A or Ac (A = C·A_c); q and Y optional, not both
};

struct Demand {
  std::string name;
  qpreduce::SparseMatrix<double> A;               // n × m (= C·A_c when given in design coordinates)
  qpreduce::Matrix<double> A_c;  // d × m, or empty
  qpreduce::Vector<double> b, q, Y;
  bool in_D = false;  // q = D·Y
};

// The demands of a directory (A_<name>.mtx or Ac_<name>.mtx, b_<name>.mtx,
// optional q_ or Y_), by name. Throws std::invalid_argument naming the file.
std::vector<DemandFiles> list_directory(const std::filesystem::path& dir);
// The demands a JSON manifest lists, paths relative to it. Throws
// std::invalid_argument naming the file and the entry.
std::vector<DemandFiles> read_manifest(const std::filesystem::path& file);
// The demand's matrices (C: the design columns, n × d; k: D's columns).
// Throws as the Matrix Market readers, naming the file and line.
Demand load_demand(const DemandFiles& f, const qpreduce::SparseMatrix<double>& C, qpreduce::Index k);

}  // namespace qpr
