// qpreduce — seeded non-graphics QP families, shared by tests,
// benchmarks, examples and `qpr qp`. Each is Eq. 1,
//     min_X ½XᵀHX − qᵀX   s.t.  AᵀX = b,     H n×n PSD, A n×m, b m, q n,
// solved again and again with a changing demand (A, b, q), together with the
// design spaces C (n×d, A ∈ Span(C) for in-design demands) and D (n×k,
// q ∈ Span(D)) of Eq. 2. Pages: docs/examples/<family>.md.
//
//   gmrf        Laplace / GMRF interpolation on an nx × ny grid. H = grid
//               Laplacian + κ²I (κ² = 0: PSD, ker H = constants). A selects
//               the observed sites, drawn per demand from a fixed set of d
//               candidate sites; C = selection of the candidates; D = the
//               polynomial trend basis (grid_trend_basis), q = D·Y.
//   trajectory  Smoothing of a path of T samples in `dims` coordinates, X
//               stacked by coordinate (index t + T·c). Per coordinate
//               H_c = D₂ᵀD₂ + λI (D₂: (T−2)×T second differences [1 −2 1]),
//               PD. Waypoints x_c(t_s) = P_s,c at stations s drawn per
//               demand from `stations` candidate times; C = selection of
//               every station row; q = λ·r with the reference path r in the
//               span of D = the first `modes` cosines cos(πjt/(T−1)) per
//               coordinate.
//   portfolio   Mean–variance portfolio with a factor model, lifted so that H
//               stays sparse: X = [w (assets); y (f factor exposures)],
//               H = γ·blkdiag(diag(σ²_idio), Ω) (Ω f×f SPD), objective
//               ½XᵀHX − αᵀy (factor views: q = [0; α], D = [0; I_f]). Every
//               demand keeps y = Fᵀw (f columns [F; −I], F n_a×f loadings,
//               each asset on the market factor and two others) and the budget
//               1ᵀw = 1, and adds sector-neutrality equalities
//               Σ_{i∈s} w_i = benchmark weight of sector s for a changing set
//               of sectors. C = [[F; −I], [1; 0], sector indicators].
//
// Off-design demands (for the Theorem 4.10 tests): `outside` constraints
// that are not in Span(C) — observations at non-candidate sites, waypoints
// at non-station times, neutrality of a random basket of assets — and
// `q_noise`·‖q‖ of Gaussian noise added to q.
#pragma once

#include "qpreduce/common.h"
#include "qpreduce/subspace.h"

#include <cstdint>
#include <string>
#include <vector>

namespace qpreduce::families {

enum class Family { Gmrf, Trajectory, Portfolio };
const char* to_string(Family family);  // "gmrf", "trajectory", "portfolio"
// Inverse of to_string; throws std::invalid_argument naming the choices.
Family parse_family(const std::string& name);

struct GmrfOptions {
  Index nx = 100, ny = 100;  // grid; n = nx·ny
  Index candidates = 200;    // d: candidate sites (sensor locations)
  Index trend = 6;           // k ≤ 10: trend columns 1, x, y, xy, x², y², …
  Index observed = 40;       // sites observed per demand (m), ≤ candidates
  double ridge = 0.0;        // κ² ≥ 0; 0 keeps H singular (ker H = constants)
  std::uint64_t seed = 1;
  bool is_valid(std::string* why) const;
};

struct TrajectoryOptions {
  Index samples = 1000;   // T ≥ 8; n = T·dims
  Index dims = 2;         // coordinates per sample (1 to 3)
  double lambda = 1e-2;   // λ > 0: tracking weight (H is PD)
  Index stations = 100;   // candidate waypoint times; d = stations·dims
  Index waypoints = 10;   // stations visited per demand; m = waypoints·dims
  Index modes = 4;        // reference cosines per coordinate; k = modes·dims
  std::uint64_t seed = 1;
  bool is_valid(std::string* why) const;
};

struct PortfolioOptions {
  Index assets = 2000;    // n_a; n = assets + factors
  Index factors = 10;     // f ≥ 3 (market + at least two others)
  Index sectors = 20;     // S ≥ 2; assets are spread over sectors round-robin
  Index neutral = 5;      // sectors constrained per demand, ≤ S − 1
  double risk_aversion = 1.0;  // γ > 0
  std::uint64_t seed = 1;
  bool is_valid(std::string* why) const;
};

// One family instance: H, the design spaces, and what demands are drawn from.
struct QpFamily {
  Family family = Family::Gmrf;
  std::uint64_t seed = 0;
  SparseMatrix<double> H;   // n × n, symmetric PSD
  SparseMatrix<double> C;   // n × d
  SparseMatrix<double> D;   // n × k
  Matrix<double> kernel;    // n × ν, orthonormal basis of ker H (ν = 0 when H is PD)
  // Family data for make_demand (meaning per family, see the options).
  GmrfOptions gmrf;
  TrajectoryOptions trajectory;
  PortfolioOptions portfolio;
  std::vector<Index> candidates;  // gmrf: candidate sites; trajectory: station times (sorted)
  Matrix<double> stations;        // trajectory: stations × dims waypoint positions
  Vector<double> benchmark;       // portfolio: S benchmark sector weights (sum 1)
  std::vector<Index> sector_of;   // portfolio: sector of each asset

  Index n() const { return H.rows(); }
  Index d() const { return C.cols(); }
  Index k() const { return D.cols(); }
  bool positive_definite() const { return kernel.cols() == 0; }
};

// Subspace options suited to the family: when H is PD, factor H itself
// (augment = false) — the portfolio's C has long columns (factor loadings,
// sector sums) whose augmentation ρCCᵀ would fill in (or push the build onto
// the SparseLU route); otherwise the defaults (augmented Cholesky).
SubspaceOptions recommended_options(const QpFamily& family);

// Sparse n×ν columns W with H + W·Wᵀ positive definite, for the cached
// Cholesky + Schur baseline (schur_baseline.h): empty when H is PD; for the
// gmrf family (ker H = constants, a connected grid) √(mean diag H)·e_i at the
// first candidate site.
SparseMatrix<double> baseline_bordering(const QpFamily& family);

// Throw std::invalid_argument on invalid options. Deterministic in the options
// (seed included).
QpFamily make_gmrf(const GmrfOptions& options);
QpFamily make_trajectory(const TrajectoryOptions& options);
QpFamily make_portfolio(const PortfolioOptions& options);

// Rows [first, end) of make_gmrf(options)'s H and D, the same entries
// without the whole matrices: for a distributed build where each process
// makes only its own rows (qpreduce::distributed::build_subspace_mumps_rows).
// C (the selection of the candidate sites) is n × d with d entries and is
// made whole by make_gmrf_design. Throws std::invalid_argument on invalid
// options or a row range outside [0, n).
struct GmrfRows {
  SparseMatrix<double> H;  // (end − first) × n
  SparseMatrix<double> D;  // (end − first) × k
};
GmrfRows make_gmrf_rows(const GmrfOptions& options, Index first, Index end);
// make_gmrf's C (n × d) and candidate sites, and its kernel's size, without H or D.
SparseMatrix<double> make_gmrf_design(const GmrfOptions& options);
// A family of roughly `size` unknowns with otherwise default options
// (gmrf: nx = ny = round(√size); trajectory: T = size/dims; portfolio:
// assets = size − factors). Throws std::invalid_argument when size < 64.
QpFamily make_family(Family family, Index size, std::uint64_t seed);

struct DemandOptions {
  Index outside = 0;     // constraints not in Span(C) (added to the in-design ones)
  double q_noise = 0.0;  // ‖noise‖ = q_noise·‖D·Y‖, noise Gaussian (q ∉ Span(D) when > 0)
  bool is_valid(std::string* why) const;
};

struct QpDemand {
  SparseMatrix<double> A;  // n × m, full column rank
  // d × m with A = C·A_c exactly (SubspaceSolver::set_constraints_in_design);
  // 0 × 0 when some constraint is off-design (outside > 0).
  Matrix<double> A_c;
  Vector<double> b;        // m
  Vector<double> Y;        // k: the in-design part of q is D·Y
  Vector<double> q;        // n: D·Y (+ noise)
  bool in_design = true;   // A ∈ Span(C) and q ∈ Span(D)
};

// Demand number `index` of the family: deterministic in (family seed, index,
// options). Throws std::invalid_argument on invalid options or when `outside`
// exceeds the sites/times/assets available.
QpDemand make_demand(const QpFamily& family, std::uint64_t index, const DemandOptions& options = {});

}  // namespace qpreduce::families
