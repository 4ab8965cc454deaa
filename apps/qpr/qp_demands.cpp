// `qpr qp`'s demands from files (qp_demands.h).
#include "qp_demands.h"

#include <qpreduce/problems/matrix_market.h>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include <fstream>
#include <map>
#include <stdexcept>
#include <utility>

namespace qpr {

namespace {

namespace fs = std::filesystem;
using qpreduce::Index;
using SpMat = qpreduce::SparseMatrix<double>;
using Vec = qpreduce::Vector<double>;
using json = nlohmann::json;

Vec read_vector(const std::string& path, Index rows) {
  qpreduce::MarketReadOptions o;
  o.rows = rows;
  o.cols = 1;
  return qpreduce::read_market_dense(path, o).col(0);
}

}  // namespace

std::vector<DemandFiles> list_directory(const fs::path& dir) {
  std::map<std::string, DemandFiles> by_name;
  for (const auto& entry : fs::directory_iterator(dir)) {
    const std::string file = entry.path().filename().string();
    if (entry.path().extension() != ".mtx") continue;
    const std::string path = entry.path().string();
    if (file.size() > 7 && file.compare(0, 3, "Ac_") == 0) {
      const std::string name = file.substr(3, file.size() - 7);
      by_name[name].name = name;
      by_name[name].Ac = path;
      continue;
    }
    if (file.size() < 7 || file[1] != '_') continue;
    const std::string name = file.substr(2, file.size() - 6);
    DemandFiles& f = by_name[name];
    f.name = name;
    switch (file[0]) {
      case 'A': f.A = path; break;
      case 'b': f.b = path; break;
      case 'q': f.q = path; break;
      case 'Y': f.Y = path; break;
      default: break;
    }
  }
  std::vector<DemandFiles> out;
  for (auto& [name, f] : by_name) {
    if (f.A.empty() && f.Ac.empty() && f.b.empty() && f.q.empty() && f.Y.empty()) continue;
    if (f.A.empty() == f.Ac.empty()) {
      throw std::invalid_argument(fmt::format("{}: demand '{}' needs exactly one of A_{}.mtx and Ac_{}.mtx", dir.string(),
                                              name, name, name));
    }
    if (f.b.empty()) throw std::invalid_argument(fmt::format("{}: demand '{}' has no b_{}.mtx", dir.string(), name, name));
    if (!f.q.empty() && !f.Y.empty()) {
      throw std::invalid_argument(fmt::format("{}: demand '{}' has both q_ and Y_ files", dir.string(), name));
    }
    out.push_back(f);
  }
  if (out.empty()) throw std::invalid_argument(fmt::format("{}: no demands (expected A_<name>.mtx, b_<name>.mtx)", dir.string()));
  return out;
}

std::vector<DemandFiles> read_manifest(const fs::path& file) {
  std::ifstream in(file);
  if (!in) throw std::invalid_argument(fmt::format("{}: cannot open file", file.string()));
  const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  qpreduce::deform::check_unique_json_keys(text, file.string());
  json doc;
  try {
    doc = json::parse(text);
  } catch (const json::exception& e) {
    // e.what() names the line and column (parse_error) or the number too
    // large for a double (out_of_range 406).
    throw std::invalid_argument(fmt::format("{}: {}", file.string(), e.what()));
  }
  const fs::path base = file.parent_path();
  if (!doc.is_object() || !doc.contains("demands") || !doc["demands"].is_array()) {
    throw std::invalid_argument(fmt::format("{}: expected an object with a \"demands\" array", file.string()));
  }
  std::vector<DemandFiles> out;
  size_t i = 0;
  for (const json& d : doc["demands"]) {
    auto field = [&](const char* key, bool required) -> std::string {
      if (!d.is_object() || !d.contains(key)) {
        if (required) throw std::invalid_argument(fmt::format("{}: demands[{}]: missing \"{}\"", file.string(), i, key));
        return "";
      }
      if (!d[key].is_string()) {
        throw std::invalid_argument(fmt::format("{}: demands[{}].{}: expected a string", file.string(), i, key));
      }
      const fs::path p = d[key].get<std::string>();
      return (p.is_absolute() ? p : base / p).string();
    };
    DemandFiles f;
    f.name = d.is_object() && d.contains("name") && d["name"].is_string() ? d["name"].get<std::string>()
                                                                           : fmt::format("{}", i);
    f.A = field("A", false);
    f.Ac = field("A_c", false);
    if (f.A.empty() == f.Ac.empty()) {
      throw std::invalid_argument(fmt::format("{}: demands[{}]: give exactly one of \"A\" and \"A_c\"", file.string(), i));
    }
    f.b = field("b", true);
    f.q = field("q", false);
    f.Y = field("Y", false);
    if (!f.q.empty() && !f.Y.empty()) {
      throw std::invalid_argument(fmt::format("{}: demands[{}]: give \"q\" or \"Y\", not both", file.string(), i));
    }
    for (const DemandFiles& earlier : out)
      if (earlier.name == f.name)
        throw std::invalid_argument(fmt::format("{}: demands[{}]: duplicate demand name '{}' (also demands[{}])",
                                                file.string(), i, f.name, &earlier - out.data()));
    out.push_back(f);
    ++i;
  }
  if (out.empty()) throw std::invalid_argument(fmt::format("{}: \"demands\" is empty", file.string()));
  return out;
}


Demand load_demand(const DemandFiles& f, const SpMat& C, Index k) {
  const Index n = C.rows();
  Demand d;
  d.name = f.name;
  if (!f.Ac.empty()) {
    qpreduce::MarketReadOptions oc;
    oc.rows = C.cols();
    d.A_c = qpreduce::read_market_dense(f.Ac, oc);
    d.A = (C * d.A_c).sparseView();
  } else {
    qpreduce::MarketReadOptions oa;
    oa.rows = n;
    d.A = qpreduce::read_market_sparse(f.A, oa);
  }
  d.b = read_vector(f.b, d.A.cols());
  if (!f.Y.empty()) {
    d.Y = read_vector(f.Y, k);
    d.in_D = true;
  } else if (!f.q.empty()) {
    d.q = read_vector(f.q, n);
  } else {
    d.q = Vec::Zero(n);
  }
  return d;
}

}  // namespace qpr
