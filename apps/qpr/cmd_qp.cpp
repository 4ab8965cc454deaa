// `qpr qp` — the engine on any QP given as Matrix Market files (docs/examples/qp_files.md).
//
//   qpr qp --H H.mtx --C C.mtx [--D D.mtx] --demands DIR|manifest.json
//          [--soft DELTA] [--check-full] [--baseline] [--no-augment] [--report FILE.json] [--out DIR]
//
// Precomputes the variational subspace of (H, C, D) once, then solves every
// demand (A, b, q) of Eq. 1 in the subspace and reports, per demand: the
// reduced time, and with --check-full the full sparse KKT solve's time, the
// d_H error against it and (n ≤ --theorem-max-n) the Theorem 4.10 bound with
// its terms (TheoremChecker). --baseline also times a cached Cholesky of H
// plus a Schur complement per demand (schur_baseline.h).
//
// Demands. A directory holds A_<name>.mtx (n×m) or Ac_<name>.mtx (d×m, the
// constraints in design coordinates: A = C·A_c, solved with
// set_constraints_in_design, whose fast path keeps M_q factored when A_c is
// sparse), b_<name>.mtx (m×1) and optionally q_<name>.mtx
// (n×1; missing: q = 0) or Y_<name>.mtx (k×1: q = D·Y). A JSON manifest lists
// them instead ("A_c" may replace "A"):
//   {"demands": [{"name": "d0", "A": "A0.mtx", "b": "b0.mtx", "q": "q0.mtx"}, ...]}
// with paths relative to the manifest ("Y" may replace "q").
//
// Exit codes: 0 success; 1 a bound was violated; 2 bad input (the message
// names the file and line); 3 a numerical failure (precompute or a demand).
#include "commands.h"
#include "guard.h"

#include <qpreduce/full_solve.h>
#include <qpreduce/problems/matrix_market.h>
#include <qpreduce/theorem.h>
#include <qpreduce/problems/schur_baseline.h>
#include <qpreduce/subspace_solver.h>

#include <CLI/CLI.hpp>
#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace qpr {

namespace {

namespace fs = std::filesystem;
using qpreduce::Index;
using SpMat = qpreduce::SparseMatrix<double>;
using Vec = qpreduce::Vector<double>;
using json = nlohmann::json;

struct Options {
  std::string H, C, D, demands, report, out;
  double soft = 0.0;  // 0: hard constraints
  bool check_full = false;
  bool baseline = false;
  bool no_augment = false;  // H PD: factor H itself (SubspaceOptions::augment = false)
  Index theorem_max_n = 3000;  // the bound is a dense analysis (n×n eigendecomposition)
};

struct DemandFiles {
  std::string name, A, Ac, b, q, Y;  // A or Ac (A = C·A_c); q and Y optional, not both
};

struct Demand {
  std::string name;
  SpMat A;               // n × m (= C·A_c when given in design coordinates)
  qpreduce::Matrix<double> A_c;  // d × m, or empty
  Vec b, q, Y;
  bool in_D = false;  // q = D·Y
};

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

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
  json doc;
  try {
    doc = json::parse(in);
  } catch (const json::parse_error& e) {
    // e.what() names the line and column.
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
    out.push_back(f);
    ++i;
  }
  if (out.empty()) throw std::invalid_argument(fmt::format("{}: \"demands\" is empty", file.string()));
  return out;
}

Vec read_vector(const std::string& path, Index rows) {
  qpreduce::MarketReadOptions o;
  o.rows = rows;
  o.cols = 1;
  return qpreduce::read_market_dense(path, o).col(0);
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

json finite_or_null(double v) { return std::isfinite(v) ? json(v) : json(nullptr); }

json bound_json(const qpreduce::TheoremCheck& c) {
  const qpreduce::TheoremBound& b = c.bound;
  return {{"status", qpreduce::to_string(c.status)},
          {"message", c.message},
          {"bound", finite_or_null(b.bound)},
          {"refined_bound", finite_or_null(b.refined_bound)},
          {"error", c.practical_error},
          {"violation", c.practical_violation()},
          {"covered", c.practical_covered},
          {"q_residual", b.q_residual},
          {"A_residual", b.A_residual},
          {"rho", b.rho},
          {"omega", finite_or_null(b.omega)},
          {"beta1", finite_or_null(b.beta1)},
          {"beta2", finite_or_null(b.beta2)},
          {"Delta", finite_or_null(b.Delta)},
          {"norm_q_hat", b.norm_q_hat},
          {"norm_b_hat", b.norm_b_hat},
          {"norm_A_pinv", finite_or_null(b.norm_A_pinv)},
          {"slack", c.slack}};
}

// Columns that make H + W·Wᵀ PD when H is only PSD: √ρ·C (sparse), ρ as the
// engine's default (ker H ∩ ker Cᵀ = {0} is required of the design anyway).
SpMat bordering_columns(const SpMat& H, const SpMat& C) {
  const double mean_diag = H.diagonal().cwiseAbs().mean();
  const double mean_col = C.squaredNorm() / static_cast<double>(std::max<Index>(1, C.cols()));
  return std::sqrt(mean_diag / std::max(mean_col, 1e-300)) * C;
}

int run_qp(const Options& opt) {
  // ---- inputs: read and check everything before any expensive step ----
  qpreduce::MarketReadOptions oh;
  oh.require_symmetric = true;
  const SpMat H = qpreduce::read_market_sparse(opt.H, oh);
  const Index n = H.rows();
  qpreduce::MarketReadOptions on;
  on.rows = n;
  const SpMat C = qpreduce::read_market_sparse(opt.C, on);
  const SpMat D = opt.D.empty() ? SpMat(n, 0) : qpreduce::read_market_sparse(opt.D, on);
  const fs::path dpath = opt.demands;
  if (!fs::exists(dpath)) throw std::invalid_argument(fmt::format("{}: no such file or directory", opt.demands));
  const std::vector<DemandFiles> files = fs::is_directory(dpath) ? list_directory(dpath) : read_manifest(dpath);
  std::vector<Demand> demands;
  for (const DemandFiles& f : files) demands.push_back(load_demand(f, C, D.cols()));
  if (D.cols() == 0) {
    for (const Demand& d : demands)
      if (d.in_D) throw std::invalid_argument(fmt::format("demand '{}': Y given but no --D", d.name));
  }
  if (!opt.out.empty()) fs::create_directories(opt.out);

  // ---- precompute ----
  qpreduce::SubspaceOptions sopt;
  sopt.augment = !opt.no_augment;
  qpreduce::SubspaceSolver<double> solver;
  const qpreduce::SubspaceSummary pre = solver.precompute(H, C, D, sopt);
  fmt::print("precompute: {}\n", pre.brief_report());
  if (!pre.ok()) {
    fmt::print(stderr, "qpr qp: precompute failed: {}\n", pre.message);
    return 3;
  }
  qpreduce::ConstraintOptions copt;
  if (opt.soft > 0.0) {
    copt.soft = true;
    copt.delta = opt.soft;
  }
  std::optional<qpreduce::TheoremChecker> checker;
  std::string theorem_skipped;
  if (!opt.check_full) theorem_skipped = "needs --check-full";
  else if (copt.soft) theorem_skipped = "soft constraints (Theorem 4.10 is about hard constraints)";
  else if (n > opt.theorem_max_n) theorem_skipped = fmt::format("n = {} > --theorem-max-n = {} (dense analysis)", n, opt.theorem_max_n);
  else {
    checker.emplace();
    const qpreduce::TheoremSetupSummary ts = checker->precompute(H, C, D);
    if (!ts.ok()) {
      theorem_skipped = "setup failed: " + ts.message;
      checker.reset();
    }
  }
  qpreduce::CachedCholeskySchur baseline;
  std::string baseline_note;
  double baseline_precompute = 0.0;
  if (opt.baseline) {
    qpreduce::SchurBaselineSummary bs = baseline.precompute(H, SpMat(n, 0));
    baseline_note = "factor of H";
    if (!bs.ok()) {
      bs = baseline.precompute(H, bordering_columns(H, C));
      baseline_note = "factor of H + ρ·CCᵀ, bordered (H is not PD)";
    }
    if (!bs.ok()) {
      fmt::print(stderr, "qpr qp: baseline precompute failed: {}\n", bs.message);
      return 3;
    }
    baseline_precompute = bs.seconds;
  }

  // ---- demands ----
  json records = json::array();
  int failures = 0, violations = 0;
  Vec w(solver.p()), qr(solver.p()), X(n), X_full, X_base;
  fmt::print("{:<12} {:>5} {:>12} {:>12} {:>12} {:>12} {:>12}\n", "demand", "m", "reduced ms", "full ms",
             "baseline ms", "d_H error", "bound");
  for (const Demand& d : demands) {
    json r = {{"name", d.name}, {"m", d.A.cols()}, {"design_coordinates", d.A_c.size() > 0}};
    const auto t0 = std::chrono::steady_clock::now();
    // In design coordinates A_r = [A_cᵀ 0]: no product with the n × m A.
    const qpreduce::ConstraintSummary cs =
        d.A_c.size() > 0 ? solver.set_constraints_in_design(d.A_c, copt) : solver.set_constraints(d.A, copt);
    const double t_op = seconds_since(t0);
    r["status"] = qpreduce::to_string(cs.status);
    r["message"] = cs.message;
    if (!cs.usable()) {
      ++failures;
      fmt::print(stderr, "qpr qp: demand '{}': {}\n", d.name, cs.message);
      records.push_back(r);
      continue;
    }
    const auto t1 = std::chrono::steady_clock::now();
    if (d.in_D) {
      solver.solve_in_D(d.b, d.Y, w);
    } else {
      solver.reduce_linear_term(d.q, qr);
      solver.solve(d.b, qr, w);
    }
    const double t_solve = seconds_since(t1);
    const auto t2 = std::chrono::steady_clock::now();
    solver.reconstruct(w, X);
    const double t_recon = seconds_since(t2);
    const double reduced = t_op + t_solve + t_recon;
    r["reduced_seconds"] = reduced;
    r["set_constraints_seconds"] = t_op;
    r["solve_seconds"] = t_solve;
    r["reconstruct_seconds"] = t_recon;
    r["fast_path"] = cs.fast_path;
    r["factored"] = cs.factored;  // A_c demands: M_q kept factored (subspace_solver.h)
    const Vec q = d.in_D ? Vec(D * d.Y) : d.q;
    r["constraint_residual"] = (d.A.transpose() * X - d.b).norm() / std::max(1.0, d.b.norm());

    double full_s = std::nan(""), base_s = std::nan(""), err = std::nan(""), bound = std::nan("");
    if (opt.check_full) {
      const auto t3 = std::chrono::steady_clock::now();
      const qpreduce::FullSolveSummary fsum = qpreduce::solve_full(H, d.A, d.b, q, &X_full, sopt);
      full_s = seconds_since(t3);
      r["full_seconds"] = full_s;
      r["full_status"] = qpreduce::to_string(fsum.status);
      if (fsum.ok()) {
        err = qpreduce::h_distance(H, X, X_full);
        const double scale = std::sqrt(std::max(0.0, X_full.dot(H * X_full)));
        r["dH_error"] = err;
        r["dH_rel_error"] = scale > 0 ? err / scale : err;
        r["rel_error"] = (X - X_full).norm() / std::max(1e-300, X_full.norm());
        r["speedup_vs_full"] = full_s / reduced;
      } else {
        ++failures;
        fmt::print(stderr, "qpr qp: demand '{}': full solve failed: {}\n", d.name, fsum.message);
      }
      if (checker) {
        const qpreduce::TheoremCheck c = checker->check(d.A, d.b, q);
        r["theorem"] = bound_json(c);
        bound = c.bound.bound;
        violations += c.practical_violation();
      } else {
        r["theorem"] = {{"status", "skipped"}, {"message", theorem_skipped}};
      }
    }
    if (opt.baseline) {
      const qpreduce::SchurBaselineSummary bsum = baseline.solve(d.A, d.b, q, &X_base);
      base_s = bsum.seconds;
      r["baseline_seconds"] = base_s;
      r["baseline_status"] = qpreduce::to_string(bsum.status);
      r["speedup_vs_baseline"] = base_s / reduced;
      if (bsum.ok()) r["baseline_dH_error"] = qpreduce::h_distance(H, X, X_base);
    }
    if (!opt.out.empty()) qpreduce::write_market((fs::path(opt.out) / ("X_" + d.name + ".mtx")).string(), X);
    // Columns that were not computed (no --check-full, --baseline, or theorem skipped) print "-".
    auto cell = [](double v, const char* spec) { return std::isnan(v) ? std::string("-") : fmt::format(spec, v); };
    fmt::print("{:<12} {:>5} {:>12.3f} {:>12} {:>12} {:>12} {:>12}\n", d.name, d.A.cols(), 1e3 * reduced,
               cell(1e3 * full_s, "{:.3f}"), cell(1e3 * base_s, "{:.3f}"), cell(err, "{:.3e}"), cell(bound, "{:.3e}"));
    records.push_back(r);
  }

  if (!opt.report.empty()) {
    json doc = {{"command", "qpr qp"},
                {"H", opt.H},
                {"C", opt.C},
                {"D", opt.D},
                {"demands_source", opt.demands},
                {"n", n},
                {"d", C.cols()},
                {"k", D.cols()},
                {"soft", opt.soft > 0.0},
                {"delta", opt.soft},
                {"precompute", {{"status", qpreduce::to_string(pre.status)},
                                {"message", pre.message},
                                {"seconds", pre.total_seconds},
                                {"kkt_residual", pre.kkt_residual}}},
                {"theorem_skipped", theorem_skipped.empty() ? json(nullptr) : json(theorem_skipped)},
                {"failures", failures},
                {"violations", violations},
                {"demands", records}};
    if (opt.baseline) doc["baseline"] = {{"precompute_seconds", baseline_precompute}, {"factor", baseline_note}};
    std::ofstream out(opt.report, std::ios::binary);
    out << doc.dump(2) << "\n";
    out.close();
    if (!out) throw std::invalid_argument(fmt::format("{}: cannot write the report", opt.report));
  }
  if (violations > 0) {
    fmt::print(stderr, "qpr qp: Theorem 4.10 bound violated on {} demand(s)\n", violations);
    return 1;
  }
  return failures > 0 ? 3 : 0;
}

}  // namespace

void register_qp(CLI::App& app) {
  auto opt = std::make_shared<Options>();
  CLI::App* cmd = app.add_subcommand(
      "qp",
      "Solve many demands (A, b, q) of one QP min ½XᵀHX − qᵀX s.t. AᵀX = b from Matrix Market files through the "
      "variational subspace of (H, C, D). Exit code 1: bound violated; 2: bad input; 3: numerical failure.");
  cmd->add_option("--H", opt->H, "H.mtx: n×n symmetric PSD Hessian")->required();
  cmd->add_option("--C", opt->C, "C.mtx: n×d constraint design space")->required();
  cmd->add_option("--D", opt->D, "D.mtx: n×k linear-term design space (optional)");
  cmd->add_option("--demands", opt->demands,
                  "directory of A_<name>.mtx, b_<name>.mtx [, q_<name>.mtx | Y_<name>.mtx], or a JSON manifest")
      ->required();
  cmd->add_option("--soft", opt->soft, "soft constraints with weight DELTA (Eq. 18) instead of hard ones")
      ->check(CLI::PositiveNumber);
  cmd->add_flag("--check-full", opt->check_full,
                "also solve every demand in full (sparse KKT): time, d_H error, Theorem 4.10 bound");
  cmd->add_flag("--baseline", opt->baseline, "also time a cached Cholesky of H plus a Schur complement per demand");
  cmd->add_flag("--no-augment", opt->no_augment,
                "H is positive definite: factor H itself instead of H + ρCCᵀ (for C with long columns)");
  cmd->add_option("--theorem-max-n", opt->theorem_max_n, "largest n for the (dense) Theorem 4.10 analysis")
      ->capture_default_str();
  cmd->add_option("--report", opt->report, "write a JSON report (per-demand times, errors, bound terms)");
  cmd->add_option("--out", opt->out, "write X_<name>.mtx for every demand into this directory");
  cmd->callback([opt] { run_guarded("qp", [&] { return run_qp(*opt); }); });
}

}  // namespace qpr
