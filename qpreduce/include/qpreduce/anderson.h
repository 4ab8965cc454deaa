// qpreduce — Anderson acceleration (type II) of a fixed-point iteration
// x ← G(x).
//
// Walker & Ni, "Anderson acceleration for fixed-point iterations" (SINUM
// 2011), in the form of Peng et al., "Anderson Acceleration for Geometry
// Optimization and Physics Simulation" (SIGGRAPH 2018), Algorithm 1. With the
// residual f_k = G(x_k) − x_k and the last m differences
//     ΔF = [f_{k−m+1} − f_{k−m}, …, f_k − f_{k−1}]           (n × m)
//     ΔG = [G(x_{k−m+1}) − G(x_{k−m}), …, G(x_k) − G(x_{k−1})] (n × m)
// one step is
//     θ* = argmin_θ ‖f_k − ΔF·θ‖²,      x_{k+1} = G(x_k) − ΔG·θ*.
// θ* comes from the normal equations (ΔFᵀΔF + λI)θ = ΔFᵀf_k, with the Gram
// matrix ΔFᵀΔF (m × m, m ≤ 16) and the right-hand side ΔFᵀf_k updated by one
// column per step (O(n·m), one pass writing the new differences) and solved
// by Cholesky (LDLT if that fails); λ = 1e-12 · max diag(ΔFᵀΔF) only keeps
// nearly dependent differences from blowing θ up (it changes θ by a relative
// ~1e-12 when ΔF is well conditioned).
//
// AndersonAcceleration does not know the energy; SafeguardedAnderson adds
// the safeguard of Peng et al. (an extrapolated x_{k+1} whose energy is
// above the last accepted one is refused: the caller takes the plain step
// G(x_k) and the history restarts), which the reduced rounds
// (Alternation) and the full-space refine both use.
//
// Affine constraints are preserved: x_{k+1} is an affine combination (the
// weights sum to one) of G's outputs, so if every G(x) satisfies Ax = b so
// does x_{k+1}.
#pragma once

#include "qpreduce/common.h"

#include <Eigen/Core>

#include <string>

namespace qpreduce {

struct AndersonOptions {
  // m, the number of past differences kept, in [1, 16]. Larger windows
  // extrapolate further but cost O(n·m) per step and condition worse.
  int window = 5;

  // False with a reason, e.g. "window must be in [1, 16], got 0".
  bool is_valid(std::string* why) const;
};

class AndersonAcceleration {
 public:
  static constexpr int kMaxWindow = 16;

  // Sizes the history for iterates of n entries and clears it.
  // Throws std::invalid_argument on n < 1 or invalid options.
  void reset(Index n, const AndersonOptions& options);

  // Drops the history (after a rejected step); keeps the sizes.
  void restart();

  // One type-II step: x = x_k, gx = G(x_k) (both n); writes
  //     x_{k+1} = G(x_k) − ΔG·θ,  θ = argmin ‖f_k − ΔF·θ‖  (f = G(x) − x)
  // into out (n; out may alias gx, not x). The first step after reset or
  // restart returns gx. No heap allocation after reset.
  // Throws std::invalid_argument on sizes other than reset's n.
  void step(const Eigen::Ref<const Eigen::VectorXd>& x, const Eigen::Ref<const Eigen::VectorXd>& gx,
            Eigen::Ref<Eigen::VectorXd> out);

  int history() const { return history_; }  // number of differences held (0..window)
  Index size() const { return n_; }

 private:
  using Small = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, kMaxWindow, kMaxWindow>;
  using SmallVector = Eigen::Matrix<double, Eigen::Dynamic, 1, 0, kMaxWindow, 1>;

  void push_difference(const double* x, const double* gx);
  void solve_coefficients();

  Index n_ = 0;
  int window_ = 0;
  int history_ = 0;   // differences held, in columns [0, history_)
  int next_ = 0;      // the column the next difference overwrites
  bool has_previous_ = false;
  Eigen::MatrixXd dF_, dG_;        // n × window
  Eigen::VectorXd f_, g_prev_;     // f_k and G(x_k) of the last step (n)
  Small gram_;                     // ΔFᵀΔF, history × history in the top-left corner
  SmallVector rhs_;                // ΔFᵀf_k (window; the first history_ entries)
  SmallVector theta_, column_;
};

// Anderson steps judged by an energy the caller evaluates (Peng et al. 2018,
// Algorithm 1's safeguard). A loop reads
//     trial = propose(x, G(x))  →  energy E(trial)  →  accept(E, E_accepted)
// and on a refusal goes back to the plain step G(x).
class SafeguardedAnderson {
 public:
  // Sizes the history for iterates of n entries, clears it and the count
  // of refusals. Throws std::invalid_argument as AndersonAcceleration::reset.
  void reset(Index n, const AndersonOptions& options);
  // Drops the history and the count (a new run from a new start).
  void restart();
  // One type-II step from the accepted x with gx = G(x) (n each) into out
  // (may alias gx, not x). Returns true when out is an extrapolation, to be
  // judged by accept; false when it is gx itself (no history yet). No heap
  // allocation after reset.
  bool propose(const Eigen::Ref<const Eigen::VectorXd>& x, const Eigen::Ref<const Eigen::VectorXd>& gx,
               Eigen::Ref<Eigen::VectorXd> out);
  // An extrapolation's energy against the last accepted energy: true keeps
  // it (energy ≤ accepted + slack); false (higher, or not finite) counts a
  // refusal and restarts the history: the caller takes the plain step.
  bool accept(double energy, double accepted, double slack = 0.0);

  int rejected() const { return rejected_; }  // refusals since reset or restart
  int history() const { return anderson_.history(); }
  Index size() const { return anderson_.size(); }
  int window() const { return window_; }

 private:
  AndersonAcceleration anderson_;
  int window_ = 0;
  int rejected_ = 0;
};

}  // namespace qpreduce
