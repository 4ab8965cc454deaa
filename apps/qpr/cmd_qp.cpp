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
#include "reports.h"
#include "commands.h"
#include "guard.h"
#include "qp_demands.h"
#include "validators.h"

#include <qpreduce/util/atomic_file.h>
#include <qpreduce/deform/io/json_keys.h>
#include <qpreduce/full_solve.h>
#include <qpreduce/problems/matrix_market.h>
#include <qpreduce/theorem.h>
#include <qpreduce/problems/schur_baseline.h>
#include <qpreduce/subspace_solver.h>
#ifdef QPREDUCE_HAVE_MPI
#include <qpreduce/distributed/mumps_subspace.h>

#include "mpi_session.h"
#endif
#include <qpreduce/util/timer.h>

#include <CLI/CLI.hpp>
#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <map>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace qpr {

namespace {

namespace fs = std::filesystem;
using qpreduce::Index;
using SpMat = qpreduce::SparseMatrix<double>;
using Vec = qpreduce::Vector<double>;
using json = nlohmann::json;

// The subcommand's help line.
constexpr const char* kQpAbout =
    "Solve many demands (A, b, q) of one QP min ½XᵀHX − qᵀX s.t. AᵀX = b from Matrix Market files through the "
    "variational subspace of (H, C, D). Exit code 1: bound violated; 2: bad input; 3: numerical failure.";

struct QpOptions {
  std::string H, C, D, demands, report, out;
  double soft = 0.0;  // 0: hard constraints
  bool check_full = false;
  bool baseline = false;
  bool no_augment = false;  // H PD: factor H itself (SubspaceOptions::augment = false)
  bool strict = false;      // warnings (least-squares constraints) are failures
  std::string backend = "auto";  // "mumps": the subspace built over MPI (mpirun -np K), each rank keeping its rows
  Index theorem_max_n = 3000;  // the bound is a dense analysis (n×n eigendecomposition)
};

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

// The QP (H, C, D) and its demands, read and checked before any expensive step.
// H and D hold all n rows, except on a rank of --backend mumps that needs
// only its own (read_problem; whole() says which).
struct Problem {
  SpMat H, C, D;
  std::vector<Demand> demands;
  Index n() const { return H.cols(); }
  bool whole() const { return H.rows() == H.cols(); }
};

// rows_of: empty, the whole H and D; else rows_of(n) = [first, end), the
// rows of them to keep (each file is still read and checked whole:
// qpreduce::read_market_sparse_rows).
Problem read_problem(const QpOptions& opt, const std::function<std::pair<Index, Index>(Index n)>& rows_of = {}) {
  Problem p;
  qpreduce::MarketReadOptions oh;
  oh.require_symmetric = true;
  std::pair<Index, Index> range{0, 0};
  bool part = false;  // only some rows of H and D
  if (rows_of) {
    const Index n = qpreduce::read_market_size(opt.H, oh).first;
    range = rows_of(n);
    part = range.first != 0 || range.second != n;
  }
  p.H = part ? qpreduce::read_market_sparse_rows(opt.H, range.first, range.second, oh)
             : qpreduce::read_market_sparse(opt.H, oh);
  const Index n = p.H.cols();
  qpreduce::MarketReadOptions on;
  on.rows = n;
  p.C = qpreduce::read_market_sparse(opt.C, on);
  if (opt.D.empty()) {
    p.D = SpMat(p.H.rows(), 0);
  } else {
    p.D = part ? qpreduce::read_market_sparse_rows(opt.D, range.first, range.second, on)
               : qpreduce::read_market_sparse(opt.D, on);
  }
  const fs::path dpath = opt.demands;
  if (!fs::exists(dpath)) throw std::invalid_argument(fmt::format("{}: no such file or directory", opt.demands));
  const std::vector<DemandFiles> files = fs::is_directory(dpath) ? list_directory(dpath) : read_manifest(dpath);
  for (const DemandFiles& f : files) p.demands.push_back(load_demand(f, p.C, p.D.cols()));
  if (p.D.cols() == 0) {
    for (const Demand& d : p.demands)
      if (d.in_D) throw std::invalid_argument(fmt::format("demand '{}': Y given but no --D", d.name));
  }
  return p;
}

// What every demand is solved with: the subspace solver, and the optional
// Theorem 4.10 checker and Cholesky–Schur baseline.
struct Solvers {
  qpreduce::SubspaceOptions sopt;
  qpreduce::SubspaceSolver<double> solver;
  qpreduce::ConstraintOptions copt;
  std::optional<qpreduce::TheoremChecker> checker;
  std::string theorem_skipped;  // why there is no checker
  qpreduce::CachedCholeskySchur baseline;
  std::string baseline_note;
  double baseline_precompute = 0.0;
#ifdef QPREDUCE_HAVE_MPI
  // --backend mumps: this rank's rows of B = [N UD] (the solver on every
  // rank is restored without the basis); A_r, q_r are summed over the ranks
  // and X is gathered to rank 0, which reports.
  std::optional<qpreduce::distributed::DistributedSubspace> part;
#endif
  int rank = 0;
};


// Sets up the Theorem 4.10 checker when --check-full asks for it and it applies.
void setup_theorem(const QpOptions& opt, const Problem& p, Solvers& s) {
  if (!opt.check_full) s.theorem_skipped = "needs --check-full";
  else if (s.copt.soft) s.theorem_skipped = "soft constraints (Theorem 4.10 is about hard constraints)";
  else if (p.n() > opt.theorem_max_n)
    s.theorem_skipped = fmt::format("n = {} > --theorem-max-n = {} (dense analysis)", p.n(), opt.theorem_max_n);
  else {
    s.checker.emplace();
    const qpreduce::TheoremSetupSummary ts = s.checker->precompute(p.H, p.C, p.D);
    if (!ts.ok()) {
      s.theorem_skipped = "setup failed: " + ts.message;
      s.checker.reset();
    }
  }
}

// Factors the baseline: H itself, or H bordered when H is not PD. False (with
// a message on stderr) when both fail.
bool setup_baseline(const Problem& p, Solvers& s) {
  qpreduce::SchurBaselineSummary bs = s.baseline.precompute(p.H, SpMat(p.n(), 0));
  s.baseline_note = "factor of H";
  if (!bs.ok()) {
    bs = s.baseline.precompute(p.H, bordering_columns(p.H, p.C));
    s.baseline_note = "factor of H + ρ·CCᵀ, bordered (H is not PD)";
  }
  if (!bs.ok()) {
    fmt::print(stderr, "qpr qp: baseline precompute failed: {}\n", bs.message);
    return false;
  }
  s.baseline_precompute = bs.seconds;
  return true;
}

// Vectors reused from demand to demand.
struct Workspace {
  Vec w, qr, X, X_full, X_base;
};

// One row of the table: the columns not computed (no --check-full,
// --baseline, or theorem skipped) print "-".
struct Row {
  double reduced = 0.0, full_s = std::nan(""), base_s = std::nan(""), err = std::nan(""), bound = std::nan("");
};

struct Tally {
  int failures = 0, violations = 0;
  int warnings = 0;  // demands answered by a fallback (constraints in the least-squares sense)
};

// --check-full: the full sparse KKT solve, the d_H error against it and the
// Theorem 4.10 bound.
void check_full(const Demand& d, const Vec& q, const Problem& p, Solvers& s, Workspace& ws, json& r, Row& row,
                Tally& tally) {
  const qpreduce::Timer t3;
  const qpreduce::FullSolveSummary fsum = qpreduce::solve_full(p.H, d.A, d.b, q, &ws.X_full, s.sopt);
  row.full_s = t3.seconds();
  r["full_seconds"] = row.full_s;
  r["full_status"] = qpreduce::to_string(fsum.status);
  if (fsum.ok()) {
    row.err = qpreduce::h_distance(p.H, ws.X, ws.X_full);
    const double scale = std::sqrt(std::max(0.0, ws.X_full.dot(p.H * ws.X_full)));
    r["dH_error"] = row.err;
    r["dH_rel_error"] = scale > 0 ? row.err / scale : row.err;
    r["rel_error"] = (ws.X - ws.X_full).norm() / std::max(1e-300, ws.X_full.norm());
    r["speedup_vs_full"] = row.full_s / row.reduced;
  } else {
    ++tally.failures;
    fmt::print(stderr, "qpr qp: demand '{}': full solve failed: {}\n", d.name, fsum.message);
  }
  if (s.checker) {
    const qpreduce::TheoremCheck c = s.checker->check(d.A, d.b, q);
    r["theorem"] = bound_json(c);
    row.bound = c.bound.bound;
    tally.violations += c.practical_violation();
  } else {
    r["theorem"] = {{"status", "skipped"}, {"message", s.theorem_skipped}};
  }
}

// --baseline: the cached Cholesky plus Schur complement on the same demand.
void run_baseline(const Demand& d, const Vec& q, const Problem& p, Solvers& s, Workspace& ws, json& r, Row& row) {
  const qpreduce::SchurBaselineSummary bsum = s.baseline.solve(d.A, d.b, q, &ws.X_base);
  row.base_s = bsum.seconds;
  r["baseline_seconds"] = row.base_s;
  r["baseline_status"] = qpreduce::to_string(bsum.status);
  r["speedup_vs_baseline"] = row.base_s / row.reduced;
  if (bsum.ok()) r["baseline_dH_error"] = qpreduce::h_distance(p.H, ws.X, ws.X_base);
}

// Solves one demand in the subspace (and in full, and by the baseline, when
// asked), prints its row and returns its record.
// The demand's constraints on the solver (the on-site step). In design
// coordinates A_r = [A_cᵀ 0]: no product with the n × m A; over MPI A_r is
// summed over the ranks' rows.
qpreduce::ConstraintSummary set_demand_constraints(const Demand& d, Solvers& s) {
  qpreduce::ConstraintSummary cs;
  if (d.A_c.size() > 0) {
    cs = s.solver.set_constraints_in_design(d.A_c, s.copt);
#ifdef QPREDUCE_HAVE_MPI
  } else if (s.part) {  // A_r = Σ over the ranks of (rows of A)ᵀ·(rows of B)
    cs = s.solver.set_constraints_reduced(
        d.A, qpreduce::distributed::reduced_constraints(MPI_COMM_WORLD, *s.part, d.A), s.copt);
#endif
  } else {
    cs = s.solver.set_constraints(d.A, s.copt);
  }
  return cs;
}

// The reduced answer w for the demand's b and q (or Y), into ws.w; over MPI
// q_r is summed over the ranks' rows.
void solve_demand(const Demand& d, Solvers& s, Workspace& ws) {
  if (d.in_D) {
    s.solver.solve_in_D(d.b, d.Y, ws.w);
#ifdef QPREDUCE_HAVE_MPI
  } else if (s.part) {  // q_r = Σ over the ranks of (rows of B)ᵀ·(rows of q)
    ws.qr = qpreduce::distributed::reduced_linear_term(MPI_COMM_WORLD, *s.part, d.q);
    s.solver.solve(d.b, ws.qr, ws.w);
#endif
  } else {
    s.solver.reduce_linear_term(d.q, ws.qr);
    s.solver.solve(d.b, ws.qr, ws.w);
  }
}

// X = N·z + UD·y into ws.X (over MPI each rank its rows, gathered to rank 0).
void reconstruct_demand(Solvers& s, Workspace& ws) {
#ifdef QPREDUCE_HAVE_MPI
  if (s.part) {  // each rank its rows of X = N·z + UD·y, gathered to rank 0
    qpreduce::distributed::gather_solution(MPI_COMM_WORLD, *s.part, ws.w, 0, &ws.X);
    return;
  }
#endif
  s.solver.reconstruct(ws.w, ws.X);
}

json run_demand(const Demand& d, const QpOptions& opt, const Problem& p, Solvers& s, Workspace& ws, Tally& tally) {
  json r = {{"name", d.name}, {"m", d.A.cols()}, {"design_coordinates", d.A_c.size() > 0}};
  const qpreduce::Timer t0;
  const qpreduce::ConstraintSummary cs = set_demand_constraints(d, s);
  const double t_op = t0.seconds();
  r["status"] = qpreduce::to_string(cs.status);
  r["message"] = cs.message;
  if (!cs.usable()) {
    ++tally.failures;
    if (s.rank == 0) fmt::print(stderr, "qpr qp: demand '{}': {}\n", d.name, cs.message);
    return r;
  }
  if (cs.status != qpreduce::Status::Success) {
    // A fallback that changes what the answer means: said on stderr, not only in the report.
    ++tally.warnings;
    if (s.rank == 0) {
      fmt::print(stderr, "qpr qp: {}: demand '{}': {} ({})\n", opt.strict ? "error" : "warning", d.name,
                 qpreduce::to_string(cs.status), cs.message);
    }
    if (opt.strict) {
      ++tally.failures;
      return r;
    }
  }
  const qpreduce::Timer t1;
  solve_demand(d, s, ws);
  const double t_solve = t1.seconds();
  const qpreduce::Timer t2;
  reconstruct_demand(s, ws);
  const double t_recon = t2.seconds();
  if (s.rank != 0) return r;  // rank 0 checks, writes and prints
  Row row;
  row.reduced = t_op + t_solve + t_recon;
  r["reduced_seconds"] = row.reduced;
  r["set_constraints_seconds"] = t_op;
  r["solve_seconds"] = t_solve;
  r["reconstruct_seconds"] = t_recon;
  r["fast_path"] = cs.fast_path;
  r["factored"] = cs.factored;  // A_c demands: M_q kept factored (subspace_solver.h)
  // q = D·Y for the full solves (rank 0 holds the whole D when they run).
  const Vec q = !d.in_D ? d.q : p.whole() ? Vec(p.D * d.Y) : Vec();
  r["constraint_residual"] = (d.A.transpose() * ws.X - d.b).norm() / std::max(1.0, d.b.norm());
  if (opt.check_full) check_full(d, q, p, s, ws, r, row, tally);
  if (opt.baseline) run_baseline(d, q, p, s, ws, r, row);
  if (!opt.out.empty()) qpreduce::write_market(qpr::run_files().stage((fs::path(opt.out) / ("X_" + d.name + ".mtx")).string()), ws.X);
  auto cell = [](double v, const char* spec) { return std::isnan(v) ? std::string("-") : fmt::format(spec, v); };
  fmt::print("{:<12} {:>5} {:>12.3f} {:>12} {:>12} {:>12} {:>12}\n", d.name, d.A.cols(), 1e3 * row.reduced,
             cell(1e3 * row.full_s, "{:.3f}"), cell(1e3 * row.base_s, "{:.3f}"), cell(row.err, "{:.3e}"),
             cell(row.bound, "{:.3e}"));
  return r;
}

json report_json(const QpOptions& opt, const Problem& p, const Solvers& s, const qpreduce::SubspaceSummary& pre,
                 const Tally& tally, const json& records) {
  json doc = {{"command", "qpr qp"},
              {"H", opt.H},
              {"C", opt.C},
              {"D", opt.D},
              {"demands_source", opt.demands},
              {"n", p.n()},
              {"d", p.C.cols()},
              {"k", p.D.cols()},
              {"soft", opt.soft > 0.0},
              {"delta", opt.soft},
              {"precompute", to_json(pre.report())},  // every SubspaceSummary field (docs/formats.md)
              {"theorem_skipped", s.theorem_skipped.empty() ? json(nullptr) : json(s.theorem_skipped)},
              {"failures", tally.failures},
              {"warnings", tally.warnings},
              {"violations", tally.violations},
              {"demands", records}};
  if (opt.baseline) doc["baseline"] = {{"precompute_seconds", s.baseline_precompute}, {"factor", s.baseline_note}};
  return doc;
}

int run_qp(const QpOptions& opt) {
  if (!opt.report.empty()) qpreduce::check_destination(opt.report, "report");
  if (!opt.out.empty()) {
    qpr::run_files().create_directories(opt.out);
    qpreduce::check_destination((fs::path(opt.out) / "X_.mtx").string(), "solutions (--out)");
  }
  Problem p;
  Solvers s;
  s.sopt.augment = !opt.no_augment;
  qpreduce::SubspaceSummary pre;
  if (opt.backend == "mumps") {
#ifdef QPREDUCE_HAVE_MPI
    // Every rank reads the files and keeps only its rows of H and D (rank 0
    // the whole of them when --check-full or --baseline needs them), hands
    // MUMPS its rows and keeps its rows of B (docs/scaling.md): no rank holds
    // the n × p basis. The ranks solve every demand together (A_r and q_r
    // summed, X gathered to rank 0); rank 0 checks and reports.
    MPI_Comm_rank(MPI_COMM_WORLD, &s.rank);
    const bool whole = s.rank == 0 && (opt.check_full || opt.baseline);
    p = read_problem(opt, [whole](Index n) {
      const auto r = qpreduce::distributed::owned_rows(n, MPI_COMM_WORLD);
      return whole ? std::pair<Index, Index>{0, n} : std::pair<Index, Index>{r.begin, r.end};
    });
    const auto rows = qpreduce::distributed::owned_rows(p.n(), MPI_COMM_WORLD);
    const SpMat H_rows = p.whole() ? SpMat(p.H.middleRows(rows.begin, rows.size())) : SpMat();
    const SpMat D_rows = p.whole() ? SpMat(p.D.middleRows(rows.begin, rows.size())) : SpMat();
    s.part.emplace();
    pre = qpreduce::distributed::build_subspace_mumps_rows(MPI_COMM_WORLD, p.whole() ? H_rows : p.H, p.C,
                                                           p.whole() ? D_rows : p.D, s.sopt, {}, &*s.part);
    if (pre.ok()) {  // ‖B_j‖ for ConstraintOptions::drop_tolerance
      qpreduce::Matrix<double> norms(s.part->d + s.part->k, 1);
      norms.topRows(s.part->d) = s.part->N_rows.colwise().squaredNorm().transpose();
      norms.bottomRows(s.part->k) = s.part->UD_rows.colwise().squaredNorm().transpose();
      qpreduce::distributed::sum_over_ranks(MPI_COMM_WORLD, &norms);
      s.solver.restore_without_basis(p.n(), s.part->d, norms.col(0).cwiseSqrt(), s.part->Hr, s.part->BtD, s.sopt);
    }
    if (s.rank != 0 && !pre.ok()) return 3;
#endif
  } else {
    p = read_problem(opt);
    pre = s.solver.precompute(p.H, p.C, p.D, s.sopt);
  }
  if (s.rank == 0) fmt::print("precompute: {}\n", pre.brief_report());
  if (!pre.ok()) {
    fmt::print(stderr, "qpr qp: precompute failed: {}\n", pre.message);
    return 3;
  }
  if (opt.soft > 0.0) {
    s.copt.soft = true;
    s.copt.delta = opt.soft;
  }
  json records = json::array();
  Tally tally;
  Workspace ws{Vec(s.solver.p()), Vec(s.solver.p()), Vec(p.n()), Vec(), Vec()};
  if (s.rank != 0) {  // the other ranks of --backend mumps: their share of every demand, nothing else
    for (const Demand& d : p.demands) run_demand(d, opt, p, s, ws, tally);
    return 0;
  }
  setup_theorem(opt, p, s);
  if (opt.baseline && !setup_baseline(p, s)) return 3;

  fmt::print("{:<12} {:>5} {:>12} {:>12} {:>12} {:>12} {:>12}\n", "demand", "m", "reduced ms", "full ms",
             "baseline ms", "d_H error", "bound");
  for (const Demand& d : p.demands) records.push_back(run_demand(d, opt, p, s, ws, tally));

  if (!opt.report.empty()) write_json(qpr::run_files().stage(opt.report), report_json(opt, p, s, pre, tally, records));
  if (tally.violations > 0) {
    fmt::print(stderr, "qpr qp: Theorem 4.10 bound violated on {} demand(s)\n", tally.violations);
    return 1;
  }
  return tally.failures > 0 ? 3 : 0;
}

}  // namespace

void register_qp(CLI::App& app) {
  auto [cmd, opt] = add_command<QpOptions>(app, "qp", kQpAbout);
  add_path_option(cmd, PathRole::Input, "--H", opt->H, "H.mtx: n×n symmetric PSD Hessian")->required();
  add_path_option(cmd, PathRole::Input, "--C", opt->C, "C.mtx: n×d constraint design space")->required();
  add_path_option(cmd, PathRole::Input, "--D", opt->D, "D.mtx: n×k linear-term design space (optional)");
  add_path_option(cmd, PathRole::Input, "--demands", opt->demands,
                  "directory of A_<name>.mtx, b_<name>.mtx [, q_<name>.mtx | Y_<name>.mtx], or a JSON manifest")
      ->required();
  cmd->add_option("--soft", opt->soft, "soft constraints with weight DELTA (Eq. 18) instead of hard ones")
      ->check(number_above(0));
  cmd->add_flag("--check-full", opt->check_full,
                "also solve every demand in full (sparse KKT): time, d_H error, Theorem 4.10 bound");
  cmd->add_flag("--baseline", opt->baseline, "also time a cached Cholesky of H plus a Schur complement per demand");
  cmd->add_flag("--no-augment", opt->no_augment,
                "H is positive definite: factor H itself instead of H + ρCCᵀ (for C with long columns)");
  cmd->add_option("--theorem-max-n", opt->theorem_max_n,
                  "largest n for the (dense) Theorem 4.10 analysis of --check-full (0: never)")
      ->check(whole_number_between(0, 100000))
      ->capture_default_str();
  cmd->add_flag("--strict", opt->strict,
                "a demand whose constraints hold only in the least-squares sense is a failure (exit 3), not a warning");
  add_path_option(cmd, PathRole::Output, "--report", opt->report, "write a JSON report (per-demand times, errors, bound terms)");
  add_path_option(cmd, PathRole::OutputDirectory, "--out", opt->out, "write X_<name>.mtx for every demand into this directory");
  cmd->add_option("--backend", opt->backend,
                  "auto (one process, CHOLMOD or SparseLU) or mumps (MUMPS over MPI: mpirun -np K qpr qp …; "
                  "docs/scaling.md)")
      ->check(CLI::IsMember({"auto", "mumps"}))
      ->capture_default_str();
  cmd->callback([opt = opt, command = cmd] {
    if (opt->backend != "mumps") return run_guarded("qp", [&] { return run_qp(*opt); }, {1});
#ifdef QPREDUCE_HAVE_MPI
    run_with_mpi("qp", *command, [&](const MpiSession&) { return run_qp(*opt); }, {1});
#else
    (void)command;
    run_guarded("qp", [&]() -> int {
      throw std::invalid_argument("--backend mumps: this qpr was built without MPI and MUMPS (QPREDUCE_WITH_MPI)");
    });
#endif
  });
}

}  // namespace qpr
