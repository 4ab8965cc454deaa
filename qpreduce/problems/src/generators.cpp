#include "qpreduce/problems/generators.h"

#include <Eigen/QR>
#include <Eigen/SVD>
#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <random>

namespace qpreduce::generators {

namespace {
using Triplets = std::vector<Eigen::Triplet<double>>;

void add_edge(Triplets& t, Index a, Index b) {
  t.emplace_back(a, a, 1.0);
  t.emplace_back(b, b, 1.0);
  t.emplace_back(a, b, -1.0);
  t.emplace_back(b, a, -1.0);
}

void add_ridge(Triplets& t, Index n, double ridge) {
  if (ridge == 0.0) return;
  for (Index i = 0; i < n; ++i) t.emplace_back(i, i, ridge);
}

void require_positive(const char* what, Index v) {
  if (v <= 0) throw std::invalid_argument(fmt::format("{}: expected a positive size, got {}", what, v));
}
}  // namespace

SparseMatrix<double> grid_laplacian_2d(Index nx, Index ny, double ridge) {
  require_positive("grid_laplacian_2d: nx", nx);
  require_positive("grid_laplacian_2d: ny", ny);
  const Index n = nx * ny;
  Triplets t;
  t.reserve(static_cast<size_t>(8 * n + n));
  for (Index j = 0; j < ny; ++j)
    for (Index i = 0; i < nx; ++i) {
      const Index v = i + nx * j;
      if (i + 1 < nx) add_edge(t, v, v + 1);
      if (j + 1 < ny) add_edge(t, v, v + nx);
    }
  add_ridge(t, n, ridge);
  SparseMatrix<double> L(n, n);
  L.setFromTriplets(t.begin(), t.end());
  return L;
}

SparseMatrix<double> grid_laplacian_3d(Index nx, Index ny, Index nz, double ridge) {
  require_positive("grid_laplacian_3d: nx", nx);
  require_positive("grid_laplacian_3d: ny", ny);
  require_positive("grid_laplacian_3d: nz", nz);
  const Index n = nx * ny * nz;
  Triplets t;
  t.reserve(static_cast<size_t>(12 * n + n));
  for (Index k = 0; k < nz; ++k)
    for (Index j = 0; j < ny; ++j)
      for (Index i = 0; i < nx; ++i) {
        const Index v = i + nx * (j + ny * k);
        if (i + 1 < nx) add_edge(t, v, v + 1);
        if (j + 1 < ny) add_edge(t, v, v + nx);
        if (k + 1 < nz) add_edge(t, v, v + nx * ny);
      }
  add_ridge(t, n, ridge);
  SparseMatrix<double> L(n, n);
  L.setFromTriplets(t.begin(), t.end());
  return L;
}

Matrix<double> gaussian_matrix(Index rows, Index cols, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> normal;
  Matrix<double> M(rows, cols);
  for (Index j = 0; j < cols; ++j)
    for (Index i = 0; i < rows; ++i) M(i, j) = normal(rng);
  return M;
}

Vector<double> gaussian_vector(Index n, std::uint64_t seed) { return gaussian_matrix(n, 1, seed).col(0); }

SparseMatrix<double> random_psd(Index n, Index nullity, std::uint64_t seed, Matrix<double>* null_basis) {
  require_positive("random_psd: n", n);
  if (nullity < 0 || nullity >= n) {
    throw std::invalid_argument(fmt::format("random_psd: nullity must lie in [0, {}), got {}", n, nullity));
  }
  const Matrix<double> G = gaussian_matrix(n - nullity, n, seed);
  Matrix<double> H = G.transpose() * G;
  H = 0.5 * (H + H.transpose()).eval();
  if (null_basis) {
    // ker(H) = ker(G): the last `nullity` columns of the full Q of Gᵀ.
    Eigen::HouseholderQR<Matrix<double>> qr(G.transpose());
    const Matrix<double> Q = qr.householderQ();
    *null_basis = Q.rightCols(nullity);
  }
  return H.sparseView();
}

SparseMatrix<double> random_psd_with_condition(Index n, Index nullity, double condition, std::uint64_t seed,
                                               Matrix<double>* null_basis) {
  require_positive("random_psd_with_condition: n", n);
  if (nullity < 0 || nullity >= n) {
    throw std::invalid_argument(
        fmt::format("random_psd_with_condition: nullity must lie in [0, {}), got {}", n, nullity));
  }
  if (!(condition >= 1.0) || !std::isfinite(condition)) {
    throw std::invalid_argument(
        fmt::format("random_psd_with_condition: condition must be finite and ≥ 1, got {}", condition));
  }
  // Q of a Gaussian matrix: a random orthogonal V.
  Eigen::HouseholderQR<Matrix<double>> qr(gaussian_matrix(n, n, seed));
  const Matrix<double> V = qr.householderQ();
  const Index r = n - nullity;
  Vector<double> lambda(r);
  for (Index i = 0; i < r; ++i) lambda(i) = double(n) * (r > 1 ? std::pow(condition, -double(i) / double(r - 1)) : 1.0);
  Matrix<double> H = V.rightCols(r) * lambda.asDiagonal() * V.rightCols(r).transpose();
  H = 0.5 * (H + H.transpose()).eval();
  if (null_basis) *null_basis = V.leftCols(nullity);
  return H.sparseView();
}

SparseMatrix<double> selection(Index n, const std::vector<Index>& rows) {
  SparseMatrix<double> S(n, static_cast<Index>(rows.size()));
  Triplets t;
  for (size_t j = 0; j < rows.size(); ++j) {
    if (rows[j] < 0 || rows[j] >= n) {
      throw std::invalid_argument(fmt::format("selection: row {} out of range [0, {})", rows[j], n));
    }
    t.emplace_back(rows[j], static_cast<Index>(j), 1.0);
  }
  S.setFromTriplets(t.begin(), t.end());
  return S;
}

std::vector<Index> random_subset(Index n, Index count, std::uint64_t seed) {
  if (count < 0 || count > n) {
    throw std::invalid_argument(fmt::format("random_subset: count must lie in [0, {}], got {}", n, count));
  }
  std::vector<Index> all(static_cast<size_t>(n));
  std::iota(all.begin(), all.end(), Index(0));
  std::mt19937_64 rng(seed);
  // Partial Fisher–Yates.
  for (Index i = 0; i < count; ++i) {
    std::uniform_int_distribution<Index> pick(i, n - 1);
    std::swap(all[static_cast<size_t>(i)], all[static_cast<size_t>(pick(rng))]);
  }
  std::vector<Index> out(all.begin(), all.begin() + count);
  std::sort(out.begin(), out.end());
  return out;
}

SparseMatrix<double> gaussian_sparse(Index n, Index cols, std::uint64_t seed) {
  return gaussian_matrix(n, cols, seed).sparseView();
}

SparseMatrix<double> grid_trend_basis(Index nx, Index ny, Index k) {
  return grid_trend_basis_rows(nx, ny, k, 0, nx * ny);
}

SparseMatrix<double> grid_trend_basis_rows(Index nx, Index ny, Index k, Index first, Index end) {
  require_positive("grid_trend_basis: nx", nx);
  require_positive("grid_trend_basis: ny", ny);
  if (k < 0 || k > 10) throw std::invalid_argument(fmt::format("grid_trend_basis: k must lie in [0, 10], got {}", k));
  if (first < 0 || end < first || end > nx * ny) {
    throw std::invalid_argument(fmt::format("grid_trend_basis: rows [{}, {}) outside [0, {})", first, end, nx * ny));
  }
  // Monomials x^a y^b in graded order, on coordinates scaled to [−1, 1].
  static const int powers[10][2] = {{0, 0}, {1, 0}, {0, 1}, {1, 1}, {2, 0}, {0, 2}, {2, 1}, {1, 2}, {3, 0}, {0, 3}};
  Matrix<double> T(end - first, k);
  for (Index v = first; v < end; ++v) {
    const Index i = v % nx, j = v / nx;
    const double x = nx > 1 ? 2.0 * i / (nx - 1) - 1.0 : 0.0;
    const double y = ny > 1 ? 2.0 * j / (ny - 1) - 1.0 : 0.0;
    for (Index c = 0; c < k; ++c) T(v - first, c) = std::pow(x, powers[c][0]) * std::pow(y, powers[c][1]);
  }
  return T.sparseView();
}

}  // namespace qpreduce::generators

namespace qpreduce::generators {

SparseMatrix<double> grid_trend_basis_3d(Index nx, Index ny, Index nz, Index k) {
  require_positive("grid_trend_basis_3d: nx", nx);
  require_positive("grid_trend_basis_3d: ny", ny);
  require_positive("grid_trend_basis_3d: nz", nz);
  if (k < 0 || k > 10) {
    throw std::invalid_argument(fmt::format("grid_trend_basis_3d: k must lie in [0, 10], got {}", k));
  }
  // Monomials x^a y^b z^c in graded order.
  static const int powers[10][3] = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}, {1, 1, 0},
                                    {1, 0, 1}, {0, 1, 1}, {2, 0, 0}, {0, 2, 0}, {0, 0, 2}};
  auto coordinate = [](Index i, Index count) { return count > 1 ? 2.0 * i / (count - 1) - 1.0 : 0.0; };
  Matrix<double> T(nx * ny * nz, k);
  for (Index l = 0; l < nz; ++l)
    for (Index j = 0; j < ny; ++j)
      for (Index i = 0; i < nx; ++i) {
        const double x = coordinate(i, nx), y = coordinate(j, ny), z = coordinate(l, nz);
        for (Index c = 0; c < k; ++c)
          T(i + nx * (j + ny * l), c) =
              std::pow(x, powers[c][0]) * std::pow(y, powers[c][1]) * std::pow(z, powers[c][2]);
      }
  return T.sparseView();
}

const char* to_string(TheoremFamily family) {
  switch (family) {
    case TheoremFamily::DensePsd: return "dense-psd";
    case TheoremFamily::DensePd: return "dense-pd";
    case TheoremFamily::Grid2d: return "grid2d";
    case TheoremFamily::Grid2dRidge: return "grid2d-ridge";
    case TheoremFamily::Grid3d: return "grid3d";
    case TheoremFamily::Grid3dRidge: return "grid3d-ridge";
  }
  return "unknown";
}

std::vector<TheoremFamily> theorem_families() {
  return {TheoremFamily::DensePsd, TheoremFamily::DensePd, TheoremFamily::Grid2d,
          TheoremFamily::Grid2dRidge, TheoremFamily::Grid3d, TheoremFamily::Grid3dRidge};
}

TheoremFamily parse_theorem_family(const std::string& name) {
  std::string choices;
  for (TheoremFamily f : theorem_families()) {
    if (name == to_string(f)) return f;
    choices += choices.empty() ? "" : ", ";
    choices += to_string(f);
  }
  throw std::invalid_argument(fmt::format("unknown theorem family '{}' (choose one of {})", name, choices));
}

namespace {

// SplitMix64: independent sub-seeds from one trial seed.
std::uint64_t sub_seed(std::uint64_t seed, std::uint64_t stream) {
  std::uint64_t z = seed + 0x9E3779B97F4A7C15ull * (stream + 1);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}

// Ridge that makes the grid families positive definite. The Laplacian's
// spectrum lies in [0, 4·dim], so the condition number is 1 + 4·dim/ridge.
constexpr double kGridRidge = 0.1;
// Condition number of the dense families on the range of H: large enough to
// matter, small enough that ε = 0 reproduces to ~1e-12.
constexpr double kDenseCondition = 1e3;
// A_c is redrawn until σ_min(Kᵀ·C·A_c) ≥ kWellPosed·‖C·A_c‖_F/√n (at most
// kMaxRedraws times), so the constraints pin the ker H part of X firmly.
constexpr double kWellPosed = 0.1;
// … and cond₂(Kᵀ·C·A_c) ≤ kMaxKernelCondition: with ν = m the multipliers are
// fixed by Kᵀ(A·λ − q) = 0 and ‖X̄‖ grows like 1/σ_min(KᵀA)².
constexpr double kMaxKernelCondition = 10.0;
// … and until cond₂(C·A_c) ≤ kMaxConstraintCondition: the paper takes A to be
// well conditioned (Section 2); a nearly singular square A_c (d = m) would
// otherwise make X huge and every error a matter of conditioning.
constexpr double kMaxConstraintCondition = 100.0;
constexpr int kMaxRedraws = 64;
// Smallest accepted size: d + k ≤ 18 design columns must fit in rank(H).
constexpr Index kMinTheoremSize = 24;

bool is_dense(TheoremFamily family) {
  return family == TheoremFamily::DensePsd || family == TheoremFamily::DensePd;
}

struct TheoremDims {
  Index d, k, m;  // controls (columns of C), design columns of D, constraints
};

// Dimensions first, from their own stream, so they do not depend on n; the
// dense PSD family then draws its nullity from the same stream.
TheoremDims draw_dimensions(std::mt19937_64& rng) {
  const Index d = std::uniform_int_distribution<Index>(4, 12)(rng);
  const Index k = std::uniform_int_distribution<Index>(1, 6)(rng);
  const Index m = std::uniform_int_distribution<Index>(1, std::min<Index>(d, 6))(rng);
  return {d, k, m};
}

// Fills H, kernel, C and D for the family; returns the actual n (the grid
// families round `size` to a square or a cube).
Index draw_operators(TheoremFamily family, Index size, const TheoremDims& dims, std::uint64_t seed,
                     std::mt19937_64& rng, TheoremTrial& t) {
  const Index d = dims.d, k = dims.k, m = dims.m;
  Index n = size;
  switch (family) {
    case TheoremFamily::DensePsd:
    case TheoremFamily::DensePd: {
      // Eq. 1 has a unique solution only if ker H ∩ ker Aᵀ = {0}: ν ≤ m.
      const Index nullity =
          family == TheoremFamily::DensePsd ? std::uniform_int_distribution<Index>(1, std::min<Index>(m, 3))(rng) : 0;
      t.H = random_psd_with_condition(n, nullity, kDenseCondition, sub_seed(seed, 1), &t.kernel);
      t.C = gaussian_sparse(n, d, sub_seed(seed, 2));
      t.D = gaussian_sparse(n, k, sub_seed(seed, 3));
      break;
    }
    case TheoremFamily::Grid2d:
    case TheoremFamily::Grid2dRidge: {
      const Index s = std::max<Index>(2, static_cast<Index>(std::lround(std::sqrt(static_cast<double>(size)))));
      n = s * s;
      const bool ridge = family == TheoremFamily::Grid2dRidge;
      t.H = grid_laplacian_2d(s, s, ridge ? kGridRidge : 0.0);
      t.C = selection(n, random_subset(n, d, sub_seed(seed, 2)));
      t.D = grid_trend_basis(s, s, k);
      t.kernel = ridge ? Matrix<double>(n, 0) : Matrix<double>::Constant(n, 1, 1.0 / std::sqrt(double(n)));
      break;
    }
    case TheoremFamily::Grid3d:
    case TheoremFamily::Grid3dRidge: {
      const Index s = std::max<Index>(2, static_cast<Index>(std::lround(std::cbrt(static_cast<double>(size)))));
      n = s * s * s;
      const bool ridge = family == TheoremFamily::Grid3dRidge;
      t.H = grid_laplacian_3d(s, s, s, ridge ? kGridRidge : 0.0);
      t.C = selection(n, random_subset(n, d, sub_seed(seed, 2)));
      t.D = grid_trend_basis_3d(s, s, s, k);
      t.kernel = ridge ? Matrix<double>(n, 0) : Matrix<double>::Constant(n, 1, 1.0 / std::sqrt(double(n)));
      break;
    }
  }
  return n;
}

// Whether C·A_c is well conditioned and, when H has a kernel K, Kᵀ·C·A_c
// pins the ker H part of X firmly (see the constants above).
bool demand_well_posed(const TheoremTrial& t, Index n) {
  const Matrix<double> CAc = t.C * t.A_c;
  const Vector<double> sv = Eigen::JacobiSVD<Matrix<double>>(CAc).singularValues();
  bool ok = sv(0) <= kMaxConstraintCondition * sv(sv.size() - 1);
  if (ok && t.kernel.cols() > 0) {
    const Matrix<double> KtA = t.kernel.transpose() * CAc;  // ν × m, ν ≤ m
    const Vector<double> ksv = Eigen::JacobiSVD<Matrix<double>>(KtA).singularValues();
    const double sigma_min = ksv(ksv.size() - 1);
    ok = sigma_min >= kWellPosed * CAc.norm() / std::sqrt(double(n)) && ksv(0) <= kMaxKernelCondition * sigma_min;
  }
  return ok;
}

// Draws A_c (d × m), redrawing it until the demand is well posed.
void draw_well_posed_constraints(TheoremFamily family, Index size, const TheoremDims& dims, Index n,
                                 std::uint64_t seed, TheoremTrial& t) {
  t.A_c = gaussian_matrix(dims.d, dims.m, sub_seed(seed, 4));
  for (int attempt = 1;; ++attempt) {
    if (demand_well_posed(t, n)) break;
    if (attempt == kMaxRedraws) {
      throw std::runtime_error(fmt::format("theorem_problem({}, {}, ε, {}): no well-posed demand in {} draws",
                                           to_string(family), size, seed, kMaxRedraws));
    }
    // Redraw A_c, and for the dense families C too (KᵀC itself may be nearly
    // rank deficient, and then no A_c helps).
    t.A_c = gaussian_matrix(dims.d, dims.m, sub_seed(seed, 100 + static_cast<std::uint64_t>(attempt)));
    if (is_dense(family)) t.C = gaussian_sparse(n, dims.d, sub_seed(seed, 200 + static_cast<std::uint64_t>(attempt)));
  }
}

// Draws Y, b and the perturbation directions E (n × m) and F (n), scaled to
// the norms of C·A_c and D·Y.
void draw_demand_and_perturbations(const TheoremDims& dims, Index n, std::uint64_t seed, TheoremTrial& t) {
  t.Y = gaussian_vector(dims.k, sub_seed(seed, 5));
  t.b = gaussian_vector(dims.m, sub_seed(seed, 6));
  t.E = gaussian_matrix(n, dims.m, sub_seed(seed, 7));
  t.E *= (t.C * t.A_c).norm() / t.E.norm();
  t.F = gaussian_vector(n, sub_seed(seed, 8));
  t.F *= (t.D * t.Y).norm() / t.F.norm();
}

}  // namespace

TheoremTrial theorem_problem(TheoremFamily family, Index size, double epsilon, std::uint64_t seed) {
  if (size < kMinTheoremSize) {
    throw std::invalid_argument(
        fmt::format("theorem_problem: size: expected at least {}, got {}", kMinTheoremSize, size));
  }
  if (!(epsilon >= 0.0) || !std::isfinite(epsilon)) {
    throw std::invalid_argument(fmt::format("theorem_problem: epsilon must be finite and ≥ 0, got {}", epsilon));
  }
  TheoremTrial t;
  t.family = family;
  t.size = size;
  t.epsilon = epsilon;
  t.seed = seed;

  std::mt19937_64 rng(sub_seed(seed, 0) ^ static_cast<std::uint64_t>(family));
  const TheoremDims dims = draw_dimensions(rng);
  const Index n = draw_operators(family, size, dims, seed, rng, t);
  draw_well_posed_constraints(family, size, dims, n, seed, t);
  draw_demand_and_perturbations(dims, n, seed, t);
  t.set_epsilon(epsilon);
  return t;
}

void TheoremTrial::set_epsilon(double eps) {
  if (!(eps >= 0.0) || !std::isfinite(eps)) {
    throw std::invalid_argument(fmt::format("TheoremTrial::set_epsilon: epsilon must be finite and ≥ 0, got {}", eps));
  }
  epsilon = eps;
  A = (C * A_c + eps * E).sparseView();
  q = D * Y + eps * F;
}

}  // namespace qpreduce::generators
