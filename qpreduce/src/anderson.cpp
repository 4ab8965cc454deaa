// Anderson acceleration (type II), anderson.h.
#include "qpreduce/anderson.h"

#include "qpreduce/checks.h"

#include "simd_kernels.h"

#include <Eigen/Cholesky>
#include <fmt/format.h>

#include <stdexcept>

namespace qpreduce {

namespace {
// λ / max diag(ΔFᵀΔF) in the normal equations (anderson.h): small enough not
// to change a well-conditioned θ, large enough to keep the LDLT of a
// numerically singular Gram matrix finite.
constexpr double kRelativeRegularisation = 1e-12;
}  // namespace

bool AndersonOptions::is_valid(std::string* why) const {
  if (window < 1 || window > AndersonAcceleration::kMaxWindow) {
    if (why) *why = fmt::format("window must be in [1, {}], got {}", AndersonAcceleration::kMaxWindow, window);
    return false;
  }
  return true;
}

void AndersonAcceleration::reset(Index n, const AndersonOptions& options) {
  std::string why;
  if (!options.is_valid(&why)) throw std::invalid_argument("AndersonAcceleration: " + why);
  if (n < 1) throw std::invalid_argument(fmt::format("AndersonAcceleration: the iterate size must be at least 1, got {}", n));
  if (n == n_ && options.window == window_) {  // the same sizes (each frame's run): the history is all to drop
    restart();
    return;
  }
  n_ = n;
  window_ = options.window;
  dF_.setZero(n, window_);
  dG_.setZero(n, window_);
  f_.setZero(n);
  g_prev_.setZero(n);
  gram_.setZero(window_, window_);
  rhs_.setZero(window_);
  theta_.setZero(window_);
  column_.setZero(window_);
  restart();
}

void AndersonAcceleration::restart() {
  history_ = 0;
  next_ = 0;
  has_previous_ = false;
}

// With f_{k−1} in f_ and G(x_{k−1}) in g_prev_: writes f_k − f_{k−1} and
// G(x_k) − G(x_{k−1}) into column next_ (the oldest once the window is full)
// and f_k, G(x_k) over the previous ones, in one pass; then that row and
// column of the Gram matrix and ΔFᵀf_k. Only the new column's entry of
// ΔFᵀf_k needs a product: for the others, f_k = f_{k−1} + Δf_c gives
// Δf_jᵀf_k = Δf_jᵀf_{k−1} + (ΔFᵀΔF)_jc, the last step's entry plus the new
// Gram entry (each column's entry is so updated at most window − 1 times
// before its column is overwritten and recomputed).
void AndersonAcceleration::push_difference(const double* __restrict x, const double* __restrict gx) {
  const int c = next_;
  // Six distinct arrays (x and gx are the caller's): restrict lets the
  // compiler vectorise the pass.
  double* __restrict df = dF_.col(c).data();
  double* __restrict dg = dG_.col(c).data();
  double* __restrict f = f_.data();
  double* __restrict g = g_prev_.data();
  for (Index i = 0; i < n_; ++i) {
    const double fi = gx[i] - x[i];
    df[i] = fi - f[i];
    dg[i] = gx[i] - g[i];
    f[i] = fi;
    g[i] = gx[i];
  }
  history_ = std::min(history_ + 1, window_);
  next_ = (next_ + 1) % window_;
  detail::gemtv(dF_.data(), n_, history_, n_, df, column_.data());
  for (int j = 0; j < history_; ++j) {
    gram_(j, c) = column_(j);
    gram_(c, j) = column_(j);
    if (j != c) rhs_(j) += column_(j);
  }
  rhs_(c) = dF_.col(c).dot(f_);
}

// θ = (ΔFᵀΔF + λI)⁻¹ ΔFᵀ f_k over the h differences held. The h × h system
// (h ≤ 16) by an unblocked Cholesky on the stack: Eigen's LLT of a dynamic
// matrix costs several times the arithmetic at these sizes (callgrind, the
// deformer's accelerated rounds); Eigen's LDLT when round-off leaves a nearly
// dependent history not positive definite.
void AndersonAcceleration::solve_coefficients() {
  const int h = history_;
  double scale = 0.0;
  for (int j = 0; j < h; ++j) scale = std::max(scale, gram_(j, j));
  const double shift = kRelativeRegularisation * (scale > 0.0 ? scale : 1.0);
  double L[kMaxWindow][kMaxWindow];  // lower triangle: ΔFᵀΔF + λI = L·Lᵀ
  bool positive = true;
  for (int j = 0; j < h && positive; ++j) {
    double pivot = gram_(j, j) + shift;
    for (int k = 0; k < j; ++k) pivot -= L[j][k] * L[j][k];
    if (!(pivot > 0.0)) {
      positive = false;
      break;
    }
    L[j][j] = std::sqrt(pivot);
    for (int i = j + 1; i < h; ++i) {
      double v = gram_(i, j);
      for (int k = 0; k < j; ++k) v -= L[i][k] * L[j][k];
      L[i][j] = v / L[j][j];
    }
  }
  theta_.resize(h);
  if (positive) {
    for (int i = 0; i < h; ++i) {  // L·z = rhs
      double v = rhs_(i);
      for (int k = 0; k < i; ++k) v -= L[i][k] * theta_(k);
      theta_(i) = v / L[i][i];
    }
    for (int i = h - 1; i >= 0; --i) {  // Lᵀ·θ = z
      double v = theta_(i);
      for (int k = i + 1; k < h; ++k) v -= L[k][i] * theta_(k);
      theta_(i) = v / L[i][i];
    }
  } else {
    Small a = gram_.topLeftCorner(h, h);
    a.diagonal().array() += shift;
    theta_ = Eigen::LDLT<Small>(a).solve(rhs_.head(h));
  }
}

void AndersonAcceleration::step(const Eigen::Ref<const Eigen::VectorXd>& x, const Eigen::Ref<const Eigen::VectorXd>& gx,
                                Eigen::Ref<Eigen::VectorXd> out) {
  if (n_ == 0) throw std::invalid_argument("AndersonAcceleration::step: call reset first");
  check_size("AndersonAcceleration::step: x", n_, x.size());
  check_size("AndersonAcceleration::step: gx", n_, gx.size());
  check_size("AndersonAcceleration::step: out", n_, out.size());
  if (has_previous_) {
    push_difference(x.data(), gx.data());
  } else {
    f_ = gx - x;
    g_prev_ = gx;
  }
  has_previous_ = true;
  if (history_ > 0) solve_coefficients();
  if (history_ > 0 && !theta_.allFinite()) {  // cannot happen with λ > 0 and finite input; never return NaN
    restart();
    has_previous_ = true;
  }
  if (out.data() != gx.data()) out = gx;
  if (history_ > 0) {
    column_.head(history_) = -theta_;  // scratch: out += ΔG·(−θ)
    detail::gemv_add(dG_.data(), n_, history_, n_, column_.data(), out.data());
  }
}

void SafeguardedAnderson::reset(Index n, const AndersonOptions& options) {
  anderson_.reset(n, options);
  window_ = options.window;
  rejected_ = 0;
}

void SafeguardedAnderson::restart() {
  anderson_.restart();
  rejected_ = 0;
}

bool SafeguardedAnderson::propose(const Eigen::Ref<const Eigen::VectorXd>& x,
                                  const Eigen::Ref<const Eigen::VectorXd>& gx, Eigen::Ref<Eigen::VectorXd> out) {
  anderson_.step(x, gx, out);
  return anderson_.history() > 0;
}

bool SafeguardedAnderson::accept(double energy, double accepted, double slack) {
  if (energy <= accepted + slack) return true;  // false for NaN too
  anderson_.restart();
  ++rejected_;
  return false;
}

}  // namespace qpreduce
