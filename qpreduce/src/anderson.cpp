// Anderson acceleration (type II), anderson.h.
#include "qpreduce/anderson.h"

#include "qpreduce/support.h"

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
  f_prev_.setZero(n);
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

// Appends f_k − f_{k−1} and G(x_k) − G(x_{k−1}) as column next_ (the oldest
// once the window is full) and updates that row and column of the Gram matrix.
void AndersonAcceleration::push_difference(const Eigen::Ref<const Eigen::VectorXd>& gx) {
  const int c = next_;
  dF_.col(c) = f_ - f_prev_;
  dG_.col(c) = gx - g_prev_;
  history_ = std::min(history_ + 1, window_);
  next_ = (next_ + 1) % window_;
  column_.resize(history_);
  detail::gemtv(dF_.data(), n_, history_, n_, dF_.col(c).data(), column_.data());
  gram_.col(c).head(history_) = column_;
  gram_.row(c).head(history_) = column_.transpose();
}

// θ = (ΔFᵀΔF + λI)⁻¹ ΔFᵀ f_k over the differences held.
void AndersonAcceleration::solve_coefficients() {
  const int h = history_;
  rhs_.resize(h);
  detail::gemtv(dF_.data(), n_, h, n_, f_.data(), rhs_.data());
  Small a = gram_.topLeftCorner(h, h);
  const double scale = a.diagonal().maxCoeff();
  a.diagonal().array() += kRelativeRegularisation * (scale > 0.0 ? scale : 1.0);
  // Cholesky (no pivoting: a third of the LDLT's work at m = 5); the LDLT
  // when round-off leaves a nearly dependent history not positive definite.
  const Eigen::LLT<Small> llt(a);
  if (llt.info() == Eigen::Success) {
    theta_ = llt.solve(rhs_);
  } else {
    theta_ = Eigen::LDLT<Small>(a).solve(rhs_);
  }
}

void AndersonAcceleration::step(const Eigen::Ref<const Eigen::VectorXd>& x, const Eigen::Ref<const Eigen::VectorXd>& gx,
                                Eigen::Ref<Eigen::VectorXd> out) {
  if (n_ == 0) throw std::invalid_argument("AndersonAcceleration::step: call reset first");
  check_size("AndersonAcceleration::step: x", n_, x.size());
  check_size("AndersonAcceleration::step: gx", n_, gx.size());
  check_size("AndersonAcceleration::step: out", n_, out.size());
  f_prev_.swap(f_);  // f_{k−1} (when has_previous_); f_ is overwritten next
  f_ = gx - x;
  if (has_previous_) push_difference(gx);
  g_prev_ = gx;  // before out is written: out may alias gx
  has_previous_ = true;
  if (history_ > 0) solve_coefficients();
  if (history_ > 0 && !theta_.allFinite()) {  // cannot happen with λ > 0 and finite input; never return NaN
    restart();
    has_previous_ = true;
  }
  if (out.data() != gx.data()) out = gx;
  if (history_ > 0) {
    column_ = -theta_;  // scratch: out += ΔG·(−θ)
    detail::gemv_add(dG_.data(), n_, history_, n_, column_.data(), out.data());
  }
}

}  // namespace qpreduce
