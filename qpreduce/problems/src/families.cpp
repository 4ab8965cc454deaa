#include "qpreduce/problems/families.h"

#include "qpreduce/problems/generators.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <random>

namespace qpreduce::families {

namespace gen = qpreduce::generators;
using Triplets = std::vector<Eigen::Triplet<double>>;

namespace {

// Independent random streams from (seed, index, stream) for reproducible demands.
std::mt19937_64 stream(std::uint64_t seed, std::uint64_t index, std::uint64_t which) {
  std::seed_seq seq{static_cast<std::uint32_t>(seed), static_cast<std::uint32_t>(seed >> 32),
                    static_cast<std::uint32_t>(index), static_cast<std::uint32_t>(index >> 32),
                    static_cast<std::uint32_t>(which)};
  return std::mt19937_64(seq);
}

std::uint64_t draw_seed(std::mt19937_64& rng) { return rng(); }

bool fail(std::string* why, const std::string& s) {
  if (why) *why = s;
  return false;
}

template <typename Options>
void require_valid(const char* what, const Options& o) {
  std::string why;
  if (!o.is_valid(&why)) throw std::invalid_argument(fmt::format("{}: {}", what, why));
}

// A family with validated options, its kind, seed and options recorded.
template <typename Options>
QpFamily begin(const char* what, Family kind, const Options& o, Options QpFamily::*slot) {
  require_valid(what, o);
  QpFamily f;
  f.family = kind;
  f.seed = o.seed;
  f.*slot = o;
  return f;
}

// `count` distinct indices of [0, n) not marked in `taken`, by rejection.
std::vector<Index> draw_outside(Index n, Index count, const std::vector<char>& taken, std::mt19937_64& rng) {
  std::vector<char> used = taken;
  const Index free = n - static_cast<Index>(std::count(taken.begin(), taken.end(), char(1)));
  if (count > free) {
    throw std::invalid_argument(fmt::format("make_demand: outside: expected at most {}, got {}", free, count));
  }
  std::uniform_int_distribution<Index> pick(0, n - 1);
  std::vector<Index> out;
  while (static_cast<Index>(out.size()) < count) {
    const Index i = pick(rng);
    if (used[static_cast<size_t>(i)]) continue;
    used[static_cast<size_t>(i)] = 1;
    out.push_back(i);
  }
  return out;
}

// The smooth "true image" of the gmrf family at site i (observations b).
double image(Index i, Index nx, Index ny) {
  const double x = static_cast<double>(i % nx) / nx, y = static_cast<double>(i / nx) / ny;
  return std::sin(6.0 * x) * std::cos(4.0 * y) + 0.5 * x * y;
}

// A_c for selection demands: column j of A is column design_cols[j] of C.
void set_design_selection(const QpFamily& f, const std::vector<Index>& design_cols, const DemandOptions& o,
                          QpDemand* dem) {
  if (o.outside > 0) return;
  dem->A_c = Matrix<double>::Zero(f.d(), static_cast<Index>(design_cols.size()));
  for (size_t j = 0; j < design_cols.size(); ++j) dem->A_c(design_cols[j], static_cast<Index>(j)) = 1.0;
}

// The common tail of every demand: Y = y_scale·(Gaussian), q = D·Y, the
// in-design flag, then the optional noise on q.
void finish_demand(const QpFamily& f, double y_scale, const DemandOptions& o, std::mt19937_64& rng, QpDemand* dem) {
  dem->Y = y_scale * gen::gaussian_vector(f.k(), draw_seed(rng));
  dem->q = f.D * dem->Y;
  dem->in_design = o.outside == 0;
  if (o.q_noise <= 0.0) return;
  Vector<double> noise = gen::gaussian_vector(dem->q.size(), draw_seed(rng));
  const double scale = dem->q.norm() > 0 ? dem->q.norm() : 1.0;
  dem->q += o.q_noise * scale / noise.norm() * noise;
  dem->in_design = false;
}

QpDemand gmrf_demand(const QpFamily& f, std::uint64_t index, const DemandOptions& o) {
  const GmrfOptions& g = f.gmrf;
  std::mt19937_64 rng = stream(f.seed, index, 1);
  std::vector<Index> rows, design_cols;  // design_cols: the C column of each in-design constraint
  for (Index j : gen::random_subset(static_cast<Index>(f.candidates.size()), g.observed, draw_seed(rng))) {
    rows.push_back(f.candidates[static_cast<size_t>(j)]);
    design_cols.push_back(j);
  }
  std::vector<char> taken(static_cast<size_t>(f.n()), 0);
  for (Index c : f.candidates) taken[static_cast<size_t>(c)] = 1;
  for (Index i : draw_outside(f.n(), o.outside, taken, rng)) rows.push_back(i);
  QpDemand dem;
  dem.A = gen::selection(f.n(), rows);
  set_design_selection(f, design_cols, o, &dem);
  dem.b.resize(static_cast<Index>(rows.size()));
  for (size_t j = 0; j < rows.size(); ++j) dem.b(static_cast<Index>(j)) = image(rows[j], g.nx, g.ny);
  // Trend weights small against the data term (the prior is a pure smoother).
  finish_demand(f, 1e-3, o, rng, &dem);
  return dem;
}

QpDemand trajectory_demand(const QpFamily& f, std::uint64_t index, const DemandOptions& o) {
  const TrajectoryOptions& t = f.trajectory;
  const Index T = t.samples;
  std::mt19937_64 rng = stream(f.seed, index, 2);
  std::vector<Index> rows, design_cols;
  std::vector<double> values;
  for (Index s : gen::random_subset(t.stations, t.waypoints, draw_seed(rng)))
    for (Index c = 0; c < t.dims; ++c) {
      rows.push_back(f.candidates[static_cast<size_t>(s)] + T * c);
      design_cols.push_back(s + t.stations * c);  // C lists every station per coordinate
      values.push_back(f.stations(s, c));
    }
  std::vector<char> taken(static_cast<size_t>(T), 0);
  for (Index c : f.candidates) taken[static_cast<size_t>(c)] = 1;
  std::normal_distribution<double> normal;
  for (Index time : draw_outside(T, o.outside, taken, rng))
    for (Index c = 0; c < t.dims; ++c) {
      rows.push_back(time + T * c);
      values.push_back(normal(rng));
    }
  QpDemand dem;
  dem.A = gen::selection(f.n(), rows);
  set_design_selection(f, design_cols, o, &dem);
  dem.b = Eigen::Map<const Vector<double>>(values.data(), static_cast<Index>(values.size()));
  // Reference path r = D·Y' and q = λ·r, so q = D·Y with Y = λ·Y'.
  finish_demand(f, t.lambda, o, rng, &dem);
  return dem;
}

QpDemand portfolio_demand(const QpFamily& f, std::uint64_t index, const DemandOptions& o) {
  const PortfolioOptions& p = f.portfolio;
  const Index na = p.assets, nf = p.factors, n = f.n();
  std::mt19937_64 rng = stream(f.seed, index, 3);
  const std::vector<Index> chosen = gen::random_subset(p.sectors, p.neutral, draw_seed(rng));
  std::vector<char> none(static_cast<size_t>(na), 0);
  // Each off-design constraint: a neutral basket of `kBasket` random assets.
  constexpr Index kBasket = 10;
  const Index m = nf + 1 + p.neutral + o.outside;
  Triplets t;
  QpDemand dem;
  dem.b = Vector<double>::Zero(m);
  // y = Fᵀw: the first nf columns of C.
  for (Index j = 0; j < nf; ++j)
    for (SparseMatrix<double>::InnerIterator it(f.C, j); it; ++it) t.emplace_back(it.row(), j, it.value());
  for (Index i = 0; i < na; ++i) t.emplace_back(i, nf, 1.0);  // budget
  dem.b(nf) = 1.0;
  for (Index s = 0; s < p.neutral; ++s) {
    const Index sector = chosen[static_cast<size_t>(s)];
    for (Index i = 0; i < na; ++i)
      if (f.sector_of[static_cast<size_t>(i)] == sector) t.emplace_back(i, nf + 1 + s, 1.0);
    dem.b(nf + 1 + s) = f.benchmark(sector);
  }
  for (Index c = 0; c < o.outside; ++c)
    for (Index i : draw_outside(na, kBasket, none, rng)) t.emplace_back(i, nf + 1 + p.neutral + c, 1.0);
  dem.A.resize(n, m);
  dem.A.setFromTriplets(t.begin(), t.end());
  if (o.outside == 0) {
    // C = [[F; −I], sector indicators]: factor columns, budget = Σ sectors, chosen sectors.
    dem.A_c = Matrix<double>::Zero(f.d(), m);
    for (Index j = 0; j < nf; ++j) dem.A_c(j, j) = 1.0;
    dem.A_c.block(nf, nf, p.sectors, 1).setOnes();
    for (Index s = 0; s < p.neutral; ++s) dem.A_c(nf + chosen[static_cast<size_t>(s)], nf + 1 + s) = 1.0;
  }
  // Factor views α (annualised premia of a few per cent).
  finish_demand(f, 0.05, o, rng, &dem);
  return dem;
}

}  // namespace

const char* to_string(Family family) {
  switch (family) {
    case Family::Gmrf: return "gmrf";
    case Family::Trajectory: return "trajectory";
    case Family::Portfolio: return "portfolio";
  }
  return "unknown";
}

Family parse_family(const std::string& name) {
  for (Family f : {Family::Gmrf, Family::Trajectory, Family::Portfolio})
    if (name == to_string(f)) return f;
  throw std::invalid_argument(fmt::format("unknown family '{}' (choose one of gmrf, trajectory, portfolio)", name));
}

bool GmrfOptions::is_valid(std::string* why) const {
  if (nx < 2 || ny < 2) return fail(why, fmt::format("grid must be at least 2 × 2, got {} × {}", nx, ny));
  if (candidates < 1 || candidates > nx * ny) {
    return fail(why, fmt::format("candidates must lie in [1, {}], got {}", nx * ny, candidates));
  }
  if (trend < 0 || trend > 10) return fail(why, fmt::format("trend must lie in [0, 10], got {}", trend));
  if (observed < 1 || observed > candidates) {
    return fail(why, fmt::format("observed must lie in [1, {}], got {}", candidates, observed));
  }
  if (!(ridge >= 0.0) || !std::isfinite(ridge)) return fail(why, fmt::format("ridge must be ≥ 0, got {}", ridge));
  return true;
}

bool TrajectoryOptions::is_valid(std::string* why) const {
  if (samples < 8) return fail(why, fmt::format("samples must be ≥ 8, got {}", samples));
  if (dims < 1 || dims > 3) return fail(why, fmt::format("dims must lie in [1, 3], got {}", dims));
  if (!(lambda > 0.0) || !std::isfinite(lambda)) return fail(why, fmt::format("lambda must be > 0, got {}", lambda));
  if (stations < 1 || stations > samples / 2) {
    return fail(why, fmt::format("stations must lie in [1, {}], got {}", samples / 2, stations));
  }
  if (waypoints < 1 || waypoints > stations) {
    return fail(why, fmt::format("waypoints must lie in [1, {}], got {}", stations, waypoints));
  }
  if (modes < 0 || modes > samples / 4) return fail(why, fmt::format("modes must lie in [0, {}], got {}", samples / 4, modes));
  return true;
}

bool PortfolioOptions::is_valid(std::string* why) const {
  if (factors < 3) return fail(why, fmt::format("factors must be ≥ 3, got {}", factors));
  if (sectors < 2) return fail(why, fmt::format("sectors must be ≥ 2, got {}", sectors));
  if (assets < 2 * sectors || assets < 20) {
    return fail(why, fmt::format("assets must be ≥ max(20, 2·sectors) = {}, got {}", std::max<Index>(20, 2 * sectors),
                                 assets));
  }
  if (neutral < 0 || neutral > sectors - 1) {
    return fail(why, fmt::format("neutral must lie in [0, {}], got {}", sectors - 1, neutral));
  }
  if (!(risk_aversion > 0.0) || !std::isfinite(risk_aversion)) {
    return fail(why, fmt::format("risk_aversion must be > 0, got {}", risk_aversion));
  }
  return true;
}

bool DemandOptions::is_valid(std::string* why) const {
  if (outside < 0) return fail(why, fmt::format("outside must be ≥ 0, got {}", outside));
  if (!(q_noise >= 0.0) || !std::isfinite(q_noise)) return fail(why, fmt::format("q_noise must be ≥ 0, got {}", q_noise));
  return true;
}

QpFamily make_gmrf(const GmrfOptions& o) {
  QpFamily f = begin("make_gmrf", Family::Gmrf, o, &QpFamily::gmrf);
  const Index n = o.nx * o.ny;
  f.H = gen::grid_laplacian_2d(o.nx, o.ny, o.ridge);
  f.candidates = gen::random_subset(n, o.candidates, o.seed);
  f.C = gen::selection(n, f.candidates);
  f.D = gen::grid_trend_basis(o.nx, o.ny, o.trend);
  f.kernel = o.ridge > 0 ? Matrix<double>(n, 0) : Matrix<double>::Constant(n, 1, 1.0 / std::sqrt(double(n)));
  return f;
}

GmrfRows make_gmrf_rows(const GmrfOptions& o, Index first, Index end) {
  std::string why;
  if (!o.is_valid(&why)) throw std::invalid_argument("make_gmrf_rows: " + why);
  const Index n = o.nx * o.ny;
  if (first < 0 || end < first || end > n) {
    throw std::invalid_argument(fmt::format("make_gmrf_rows: rows [{}, {}) outside [0, {})", first, end, n));
  }
  // The grid Laplacian's rows (generators.h: −1 per grid edge, the degree
  // plus the ridge on the diagonal, summed in the same order), and the
  // trend basis's rows.
  Triplets t;
  t.reserve(static_cast<size_t>(5 * (end - first)));
  for (Index v = first; v < end; ++v) {
    const Index i = v % o.nx, j = v / o.nx;
    double degree = 0.0;
    for (const auto& [ok, u] : {std::pair<bool, Index>{i > 0, v - 1}, {i + 1 < o.nx, v + 1}, {j > 0, v - o.nx},
                                {j + 1 < o.ny, v + o.nx}}) {
      if (!ok) continue;
      t.emplace_back(v - first, u, -1.0);
      degree += 1.0;
    }
    t.emplace_back(v - first, v, degree + o.ridge);
  }
  GmrfRows rows;
  rows.H.resize(end - first, n);
  rows.H.setFromTriplets(t.begin(), t.end());
  rows.D = gen::grid_trend_basis_rows(o.nx, o.ny, o.trend, first, end);
  return rows;
}

SparseMatrix<double> make_gmrf_design(const GmrfOptions& o) {
  std::string why;
  if (!o.is_valid(&why)) throw std::invalid_argument("make_gmrf_design: " + why);
  return gen::selection(o.nx * o.ny, gen::random_subset(o.nx * o.ny, o.candidates, o.seed));
}

QpFamily make_trajectory(const TrajectoryOptions& o) {
  QpFamily f = begin("make_trajectory", Family::Trajectory, o, &QpFamily::trajectory);
  const Index T = o.samples, n = T * o.dims;
  Triplets t;
  t.reserve(static_cast<size_t>(10 * n));
  for (Index c = 0; c < o.dims; ++c) {
    const Index off = T * c;
    // D₂ᵀD₂: each row r of D₂ couples (r, r+1, r+2) with weights (1, −2, 1).
    static const double w[3] = {1.0, -2.0, 1.0};
    for (Index r = 0; r + 2 < T; ++r)
      for (int a = 0; a < 3; ++a)
        for (int b = 0; b < 3; ++b) t.emplace_back(off + r + a, off + r + b, w[a] * w[b]);
    for (Index i = 0; i < T; ++i) t.emplace_back(off + i, off + i, o.lambda);
  }
  f.H.resize(n, n);
  f.H.setFromTriplets(t.begin(), t.end());
  // Stations: interior times, away from the two ends.
  std::vector<Index> times = gen::random_subset(T - 2, o.stations, o.seed);
  for (Index& s : times) s += 1;
  f.candidates = times;
  std::vector<Index> rows;
  for (Index c = 0; c < o.dims; ++c)
    for (Index s : times) rows.push_back(s + T * c);
  f.C = gen::selection(n, rows);
  // Station positions on a smooth random curve plus a little scatter.
  const Vector<double> phase = gen::gaussian_vector(o.dims, o.seed + 1);
  const Matrix<double> scatter = 0.05 * gen::gaussian_matrix(o.stations, o.dims, o.seed + 2);
  f.stations.resize(o.stations, o.dims);
  for (Index s = 0; s < o.stations; ++s)
    for (Index c = 0; c < o.dims; ++c) {
      const double tau = static_cast<double>(times[static_cast<size_t>(s)]) / (T - 1);
      f.stations(s, c) = std::sin(2.0 * M_PI * (c + 1) * tau + phase(c)) + scatter(s, c);
    }
  Matrix<double> Dm = Matrix<double>::Zero(n, o.modes * o.dims);
  for (Index c = 0; c < o.dims; ++c)
    for (Index j = 0; j < o.modes; ++j)
      for (Index i = 0; i < T; ++i) Dm(i + T * c, j + o.modes * c) = std::cos(M_PI * j * i / double(T - 1));
  f.D = Dm.sparseView();
  f.kernel.resize(n, 0);
  return f;
}

QpFamily make_portfolio(const PortfolioOptions& o) {
  QpFamily f = begin("make_portfolio", Family::Portfolio, o, &QpFamily::portfolio);
  const Index na = o.assets, nf = o.factors, n = na + nf;
  std::mt19937_64 rng = stream(o.seed, 0, 0);
  std::normal_distribution<double> normal;
  std::uniform_real_distribution<double> idio(0.01, 0.09);  // idiosyncratic variances
  f.sector_of.resize(static_cast<size_t>(na));
  for (Index i = 0; i < na; ++i) f.sector_of[static_cast<size_t>(i)] = i % o.sectors;

  // Loadings F (na × nf): market, the asset's sector factor, one style factor.
  Triplets tf;
  for (Index i = 0; i < na; ++i) {
    const Index sector_factor = 1 + f.sector_of[static_cast<size_t>(i)] % (nf - 1);
    Index style = 1 + static_cast<Index>(rng() % static_cast<std::uint64_t>(nf - 1));
    if (style == sector_factor) style = 1 + style % (nf - 1);
    tf.emplace_back(i, 0, 1.0 + 0.3 * normal(rng));
    tf.emplace_back(i, sector_factor, 0.5 * normal(rng));
    if (style != sector_factor) tf.emplace_back(i, style, 0.5 * normal(rng));
  }
  // Factor covariance Ω = 0.04·(GGᵀ/f + 0.1·I), SPD.
  const Matrix<double> G = gen::gaussian_matrix(nf, nf, draw_seed(rng));
  Matrix<double> Omega = 0.04 * (G * G.transpose() / double(nf) + 0.1 * Matrix<double>::Identity(nf, nf));
  Omega = (0.5 * (Omega + Omega.transpose())).eval();  // exactly symmetric (the product need not be)

  Triplets th;
  for (Index i = 0; i < na; ++i) th.emplace_back(i, i, o.risk_aversion * idio(rng));
  for (Index a = 0; a < nf; ++a)
    for (Index b = 0; b < nf; ++b) th.emplace_back(na + a, na + b, o.risk_aversion * Omega(a, b));
  f.H.resize(n, n);
  f.H.setFromTriplets(th.begin(), th.end());

  // C = [[F; −I], sector indicators]  (the budget is their sum).
  Triplets tc = tf;
  for (Index j = 0; j < nf; ++j) tc.emplace_back(na + j, j, -1.0);
  for (Index i = 0; i < na; ++i) tc.emplace_back(i, nf + f.sector_of[static_cast<size_t>(i)], 1.0);
  f.C.resize(n, nf + o.sectors);
  f.C.setFromTriplets(tc.begin(), tc.end());
  Triplets td;
  for (Index j = 0; j < nf; ++j) td.emplace_back(na + j, j, 1.0);
  f.D.resize(n, nf);
  f.D.setFromTriplets(td.begin(), td.end());

  // Benchmark sector weights: positive, summing to one.
  f.benchmark.resize(o.sectors);
  for (Index s = 0; s < o.sectors; ++s) f.benchmark(s) = 0.5 + std::abs(normal(rng));
  f.benchmark /= f.benchmark.sum();
  f.kernel.resize(n, 0);
  return f;
}

QpFamily make_family(Family family, Index size, std::uint64_t seed) {
  if (size < 64) throw std::invalid_argument(fmt::format("make_family: size: expected at least 64, got {}", size));
  switch (family) {
    case Family::Gmrf: {
      GmrfOptions o;
      o.nx = o.ny = std::max<Index>(8, static_cast<Index>(std::lround(std::sqrt(double(size)))));
      o.candidates = std::min<Index>(o.candidates, o.nx * o.ny / 4);
      o.observed = std::min<Index>(o.observed, o.candidates / 2);
      o.seed = seed;
      return make_gmrf(o);
    }
    case Family::Trajectory: {
      TrajectoryOptions o;
      o.samples = size / o.dims;
      o.stations = std::min<Index>(o.stations, o.samples / 4);
      o.waypoints = std::min<Index>(o.waypoints, o.stations / 2);
      o.seed = seed;
      return make_trajectory(o);
    }
    case Family::Portfolio: {
      PortfolioOptions o;
      o.assets = size - o.factors;
      o.sectors = std::min<Index>(o.sectors, o.assets / 4);
      o.neutral = std::min<Index>(o.neutral, o.sectors - 1);
      o.seed = seed;
      return make_portfolio(o);
    }
  }
  throw std::invalid_argument("make_family: unknown family");
}

SubspaceOptions recommended_options(const QpFamily& family) {
  SubspaceOptions o;
  o.augment = !family.positive_definite();
  return o;
}

SparseMatrix<double> baseline_bordering(const QpFamily& family) {
  if (family.positive_definite()) return SparseMatrix<double>(family.n(), 0);
  // Only the gmrf family has a kernel (the constants), pinned by one site.
  return std::sqrt(family.H.diagonal().mean()) * gen::selection(family.n(), {family.candidates.front()});
}

QpDemand make_demand(const QpFamily& family, std::uint64_t index, const DemandOptions& options) {
  require_valid("make_demand", options);
  switch (family.family) {
    case Family::Gmrf: return gmrf_demand(family, index, options);
    case Family::Trajectory: return trajectory_demand(family, index, options);
    case Family::Portfolio: return portfolio_demand(family, index, options);
  }
  throw std::invalid_argument("make_demand: unknown family");
}

}  // namespace qpreduce::families
