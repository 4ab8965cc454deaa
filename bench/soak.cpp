// Soak: a long run of the public Deformer API under random handle motion,
// checking every frame and the process's resident memory (docs/robustness.md,
// "Soak"). A plain program, not a Google Benchmark fixture: one long session
// is the point, not a repeated kernel.
//
//   soak [--model cactus|bumpy_plane|builtin|PATH.off] [--frames N]
//        [--set-every K] [--seed S] [--warmup-sets W] [--energy-bound F]
//        [--energy-every E] [--rss-limit-kib L] [--json PATH] [--verbose 1]
//        [--hostile 1] [--anderson W] [--rounds R] [--cold-start-rounds C] [--trace-set N]
//        [--first-set N] [--random-rounds J]
//
// One precompute (DeformerOptions defaults: 33 linear proxies, 27 clusters,
// 8 accelerated rounds per frame), then N frames (default 10⁵); every K
// frames (default 100) a new random handle set (seeded): 1–3 single
// vertices, 4–16 single vertices, or 1–6 group handles over patches of
// 3–400 nearby vertices with random weights. Their targets follow one random
// smooth displacement field (Motion below: ‖u‖ ≤ 0.25 × the bounding-box
// diagonal, gradient bound G) and a rigid turn of up to 90° about the rest
// centroid. Every frame is checked:
//   * FrameSummary status Success (or ConstraintsLeastSquares when
//     set_handles said the set is over-determined, --hostile only);
//   * no NaN or infinity in the pose or in E′ (FrameSummary::model_energy,
//     NaN only for plain rounds, which then say why);
//   * every vertex within 3 diagonals of the rest centroid;
// and every E-th frame (default 10) and the first and last of every set,
// the classic ARAP energy E(V′) of the reconstructed pose (an SVD per
// element, so not every frame): finite and E(V′) ≤ F · G² · E(2V), F =
// --energy-bound (default 10). E(2V) = ½ Σ c_ij ‖e_ij‖² is the energy of
// doubling the rest mesh in size; G²·E(2V) bounds the energy of the pose in
// which every vertex follows the field (it meets every target), so the
// minimiser costs no more; F leaves room for the subspace and for the
// frames right after a handle set changes (8 warm-started rounds).
// Every 10th handle set is invalid (a vertex out of range, an empty handle,
// a NaN or missing weight): set_handles must refuse it with
// std::invalid_argument and a message, and the frames then go on with the
// previous handle set.
// --hostile 1 adds over-determined sets (up to 40 single vertices, or every
// vertex of a patch of 10–150 as its own handle) which the subspace cannot
// meet: set_handles solves them as soft constraints and says so
// (DeformerOptions::soften_unreachable_handles; docs/robustness.md, "Soak").
// --random-rounds J caps each frame at a number of rounds drawn from 1…J
// (seeded) in place of the time budget (the tolerance stays): frames stopped
// before their fixed point, as a loaded machine's budget stops them, but the
// same on every machine (a set whose budget-stopped rounds went wrong under load
// then fails everywhere).
// Resident memory (/proc/self/statm) is sampled after the warm-up (the first
// W handle sets, default 10, which begin with the largest set of each kind)
// and at the end: growth above L KiB (default 1024) fails. Storage for the
// per-frame samples is allocated and touched before the warm-up ends.
// Output: a summary line, then a JSON report (stdout, or --json PATH).
// Exit status 0 when nothing was violated, 1 on a violation, 2 on bad usage.
#include <qpreduce/deform/deformer/deformer.h>
#include <qpreduce/deform/energy/arap_energy.h>
#include <qpreduce/deform/io/mesh_io.h>
#include <qpreduce/deform/mesh/geometry.h>
#include <qpreduce/deform/mesh/shapes.h>

#include <qpreduce/util/atomic_file.h>
#include <qpreduce/util/cpu_features.h>
#include <qpreduce/util/timer.h>

#include <Eigen/Geometry>
#include <fmt/format.h>

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

namespace {

using namespace qpreduce;
using namespace qpreduce::deform;

struct Args {
  std::string model = "cactus";
  long frames = 100000;
  long set_every = 100;
  std::uint64_t seed = 1;
  long warmup_sets = 10;
  double energy_bound = 10.0;
  long energy_every = 10;
  double rss_limit_kib = 1024.0;
  std::string json;
  bool verbose = false;  // a line per handle set
  bool hostile = false;  // also over-determined sets (docs/robustness.md, "Soak")
  int anderson = -1;     // DeformerOptions::anderson_window (−1: the default)
  int cold_start = -1;   // DeformerOptions::cold_start_rounds (−1: the default)
  int rounds = -1;       // DeformerOptions::iterations (−1: the default)
  int random_rounds = 0;  // > 0: each frame capped at a seeded random 1…J rounds
  long trace_set = -1;   // print every frame of this handle set (E′, classic energy, residual)
  long first_set = 0;    // draw the handle sets before this one but do not run their frames
};

// Handles move at most this far (× the bounding-box diagonal) from rest.
constexpr double kMaxOffset = 0.25;
// The whole target set also turns rigidly about the rest centroid, by at most
// this angle (radians): free for the energy, a test of the global rotation.
constexpr double kMaxTurn = 1.5707963267948966;
// Vertices must stay within this many diagonals of the rest centroid.
constexpr double kMaxReach = 3.0;
// Every kInvalidEvery-th handle set is an invalid one.
constexpr long kInvalidEvery = 10;

[[noreturn]] void usage(const std::string& problem) {
  std::fprintf(stderr,
               "soak: %s\nusage: soak [--model cactus|bumpy_plane|builtin|PATH.off] [--frames N] [--set-every K]\n"
               "            [--seed S] [--warmup-sets W] [--energy-bound F] [--energy-every E]\n"
               "            [--rss-limit-kib L] [--json PATH] [--verbose 1] [--hostile 1] [--anderson W] [--rounds R]\n"
               "            [--cold-start-rounds C] [--random-rounds J]\n"
               "            [--trace-set N] [--first-set N]\n",
               problem.c_str());
  std::exit(2);
}

Args parse(int argc, char** argv) {
  Args a;
  for (int i = 1; i < argc; ++i) {
    const std::string key = argv[i];
    if (i + 1 >= argc) usage(key + " needs a value");
    const std::string value = argv[++i];
    try {
      if (key == "--model") a.model = value;
      else if (key == "--frames") a.frames = std::stol(value);
      else if (key == "--set-every") a.set_every = std::stol(value);
      else if (key == "--seed") a.seed = std::stoull(value);
      else if (key == "--warmup-sets") a.warmup_sets = std::stol(value);
      else if (key == "--energy-bound") a.energy_bound = std::stod(value);
      else if (key == "--energy-every") a.energy_every = std::stol(value);
      else if (key == "--rss-limit-kib") a.rss_limit_kib = std::stod(value);
      else if (key == "--json") a.json = value;
      else if (key == "--verbose") a.verbose = value != "0";
      else if (key == "--hostile") a.hostile = value != "0";
      else if (key == "--anderson") a.anderson = std::stoi(value);
      else if (key == "--cold-start-rounds") a.cold_start = std::stoi(value);
      else if (key == "--rounds") a.rounds = std::stoi(value);
      else if (key == "--random-rounds") a.random_rounds = std::stoi(value);
      else if (key == "--trace-set") a.trace_set = std::stol(value);
      else if (key == "--first-set") a.first_set = std::stol(value);
      else usage("unknown option " + key);
    } catch (const std::logic_error&) {
      usage(key + ": not a number: " + value);
    }
  }
  if (a.frames < 1 || a.set_every < 1 || a.energy_every < 1 || a.warmup_sets < 0 || a.first_set < 0 || a.random_rounds < 0)
    usage("--frames, --set-every and --energy-every must be ≥ 1, --warmup-sets and --random-rounds ≥ 0");
  if (!(a.energy_bound > 0) || !(a.rss_limit_kib >= 0)) usage("--energy-bound must be > 0, --rss-limit-kib ≥ 0");
  return a;
}

double resident_kib() {
  long pages = 0, resident = 0;
  std::ifstream statm("/proc/self/statm");
  statm >> pages >> resident;
  return static_cast<double>(resident) * static_cast<double>(::sysconf(_SC_PAGESIZE)) / 1024.0;
}

// The model: a Botsch–Sorkine mesh from ../shared/data, or the demo's
// built-in capped cylinder when that is absent (or asked for).
TriangleMesh load_model(const std::string& name, std::string* label) {
  const std::string dir = std::getenv("QPREDUCE_SHARED_DATA") ? std::getenv("QPREDUCE_SHARED_DATA")
                                                              : std::string(QPREDUCE_SHARED_DIR) + "/data";
  std::string path = name;
  if (name == "cactus" || name == "bumpy_plane") path = dir + "/meshes/botsch-sorkine/" + name + ".off";
  if (name != "builtin" && std::filesystem::exists(path)) {
    *label = path;
    return read_triangle_mesh(path);
  }
  if (name != "builtin") std::printf("soak: %s not found; using the built-in capped cylinder\n", path.c_str());
  *label = "built-in capped cylinder (qpr demo's, 4,802 vertices)";
  return shapes::capped_cylinder(1.0, 12.0, 60, 80);
}

// ---------------------------------------------------------------- handle sets

enum class SetKind { FewPoints, ManyPoints, Region, Groups, Invalid };

const char* to_string(SetKind k) {
  switch (k) {
    case SetKind::FewPoints: return "few-points";
    case SetKind::ManyPoints: return "many-points";
    case SetKind::Region: return "region";
    case SetKind::Groups: return "groups";
    case SetKind::Invalid: return "invalid";
  }
  return "?";
}

// A handle set and how its handles move: every target follows one smooth
// displacement field u(p, t) = Σ_k a_k sin(κ_k·p + ω_k t + φ_k) (kModes
// waves) of its rest point p, the whole set then turned about the rest
// centroid by an angle growing to `turn` about `axis`. The field's gradient
// is bounded, ‖∇u‖₂ ≤ G = Σ_k ‖a_k‖‖κ_k‖, so the pose "every vertex follows
// the field" meets every target at a classic ARAP energy of about G²·E(2V)
// (its edges are e′ ≈ (I + ∇u)e; R = I gives ‖∇u·e‖² ≤ G²‖e‖²), and the
// turn costs nothing: the minimiser is no dearer than that.
constexpr int kModes = 3;
struct Motion {
  Handles handles;
  Vertices rest;  // one row per point handle
  Eigen::Matrix<double, kModes, 3> amp, wave;
  Eigen::Matrix<double, kModes, 1> omega, phase;
  double gradient = 0.0;  // G
  Eigen::Vector3d axis = Eigen::Vector3d::UnitZ();
  double turn = 0.0;
  long t = 0;  // frames since the set was made
};

class SetMaker {
 public:
  SetMaker(const Vertices& V, std::uint64_t seed) : V_(V), rng_(seed) {
    diagonal_ = bounding_box_diagonal(V);
    centroid_ = V.colwise().mean().transpose();
  }
  double diagonal() const { return diagonal_; }
  const Eigen::Vector3d& centroid() const { return centroid_; }

  // The kind of set number `index`: every kInvalidEvery-th invalid; the
  // first four valid sets are the largest of each kind (so that the warm-up
  // reaches the memory high-water mark), then random kinds and sizes.
  // Hostile runs add Region sets and many-points sets past the subspace's
  // linear degrees of freedom (over-determined: least squares).
  SetKind kind_of(long index, bool hostile) {
    static constexpr SetKind kinds[] = {SetKind::FewPoints, SetKind::ManyPoints, SetKind::Groups, SetKind::Region};
    const long count = hostile ? 4 : 3;
    if (index % kInvalidEvery == kInvalidEvery - 1) return SetKind::Invalid;
    if (index < count) return kinds[index];
    return kinds[uniform_int(0, count - 1)];
  }

  // Handles of a valid set; `largest` takes the top of each size range.
  Handles make(SetKind kind, bool largest, bool hostile) {
    Handles h;
    const Index n = V_.rows();
    auto size = [&](long lo, long hi) { return largest ? hi : uniform_int(lo, hi); };
    switch (kind) {
      case SetKind::FewPoints:  // 1–3 single vertices
        for (long i = 0, k = size(1, 3); i < k; ++i) h.points.push_back({{random_vertex()}, {}});
        break;
      case SetKind::ManyPoints:  // 4–16 single vertices anywhere (hostile: 4–40)
        for (long i = 0, k = size(4, hostile ? 40 : 16); i < k; ++i) h.points.push_back({{random_vertex()}, {}});
        break;
      case SetKind::Region:  // every vertex of a patch of 10–150 as its own handle
        for (Index v : neighbourhood(random_vertex(), std::min<Index>(n, size(10, 150))))
          h.points.push_back({{v}, {}});
        break;
      case SetKind::Groups:  // 1–6 group handles, each a patch of 3–400 with random weights summing to 1
        for (long g = 0, k = size(1, 6); g < k; ++g) {
          PointHandle ph;
          ph.vertices = neighbourhood(random_vertex(), std::min<Index>(n, size(3, 400)));
          double total = 0.0;
          for (size_t i = 0; i < ph.vertices.size(); ++i) ph.weights.push_back(uniform(0.1, 1.0)), total += ph.weights.back();
          for (double& w : ph.weights) w /= total;
          h.points.push_back(std::move(ph));
        }
        break;
      case SetKind::Invalid:
        break;
    }
    return h;
  }

  // A handle set that set_handles must refuse, and what is wrong with it.
  Handles make_invalid(std::string* what) {
    Handles h = make(SetKind::ManyPoints, false, false);
    const Index n = V_.rows();
    PointHandle& ph = h.points[static_cast<size_t>(uniform_int(0, static_cast<long>(h.points.size()) - 1))];
    switch (uniform_int(0, 4)) {
      case 0: ph.vertices[0] = n + uniform_int(0, 1000), *what = "a vertex past the end"; break;
      case 1: ph.vertices[0] = -1 - uniform_int(0, 1000), *what = "a negative vertex"; break;
      case 2: ph.vertices.clear(), *what = "a handle without vertices"; break;
      case 3:
        ph.vertices = neighbourhood(ph.vertices[0], std::min<Index>(n, 8));
        ph.weights.assign(ph.vertices.size(), 1.0 / 8);
        ph.weights[3] = std::numeric_limits<double>::quiet_NaN();
        *what = "a NaN weight";
        break;
      default:
        ph.vertices = neighbourhood(ph.vertices[0], std::min<Index>(n, 8));
        ph.weights.assign(ph.vertices.size() - 1, 1.0 / 8);
        *what = "a weight missing";
        break;
    }
    return h;
  }

  // The motion of a (valid) handle set: each wave's amplitude at most
  // kMaxOffset·diagonal/kModes (so ‖u‖ ≤ kMaxOffset·diagonal), wavelengths
  // of 1–4 diagonals, periods of 20–400 frames.
  Motion motion(Handles handles) {
    Motion m;
    const Index k = static_cast<Index>(handles.points.size());
    m.rest.setZero(k, 3);
    for (Index h = 0; h < k; ++h) {
      const PointHandle& ph = handles.points[static_cast<size_t>(h)];
      for (size_t i = 0; i < ph.vertices.size(); ++i)
        m.rest.row(h) += (ph.weights.empty() ? 1.0 : ph.weights[i]) * V_.row(ph.vertices[i]);
    }
    const double pi = std::acos(-1.0);
    for (int w = 0; w < kModes; ++w) {
      const double a = uniform(0, kMaxOffset * diagonal_ / kModes), kappa = 2 * pi / (diagonal_ * uniform(1, 4));
      m.amp.row(w) = a * random_direction().transpose();
      m.wave.row(w) = kappa * random_direction().transpose();
      m.omega(w) = 2 * pi / uniform(20, 400);
      m.phase(w) = uniform(0, 2 * pi);
      m.gradient += a * kappa;
    }
    m.axis = random_direction();
    m.turn = uniform(0, kMaxTurn);
    m.handles = std::move(handles);
    return m;
  }

 private:
  long uniform_int(long lo, long hi) { return std::uniform_int_distribution<long>(lo, hi)(rng_); }
  double uniform(double lo, double hi) { return std::uniform_real_distribution<double>(lo, hi)(rng_); }
  Eigen::Vector3d random_direction() {
    std::normal_distribution<double> g;
    Eigen::Vector3d d(g(rng_), g(rng_), g(rng_));
    return d.norm() > 0 ? d.normalized() : Eigen::Vector3d::UnitX();
  }
  Index random_vertex() { return static_cast<Index>(uniform_int(0, static_cast<long>(V_.rows()) - 1)); }

  // The `count` vertices nearest to `centre` (Euclidean): a patch.
  std::vector<Index> neighbourhood(Index centre, Index count) {
    const Index n = V_.rows();
    order_.resize(static_cast<size_t>(n));
    for (Index v = 0; v < n; ++v) order_[static_cast<size_t>(v)] = {(V_.row(v) - V_.row(centre)).squaredNorm(), v};
    std::nth_element(order_.begin(), order_.begin() + (count - 1), order_.end());
    std::vector<Index> out;
    for (Index i = 0; i < count; ++i) out.push_back(order_[static_cast<size_t>(i)].second);
    return out;
  }

  const Vertices& V_;
  std::mt19937_64 rng_;
  double diagonal_ = 0.0;
  Eigen::Vector3d centroid_;
  std::vector<std::pair<double, Index>> order_;
};

// Targets of the motion's current frame, into `targets` (sized once per set).
void targets_at(const Motion& m, const Eigen::Vector3d& centroid, HandleTargets* targets) {
  const double t = static_cast<double>(m.t);
  // The turn grows smoothly from 0 to m.turn over the first 100 frames.
  const double angle = m.turn * (1.0 - std::cos(std::acos(-1.0) * std::min(t, 100.0) / 100.0)) / 2.0;
  const Eigen::Matrix3d R = Eigen::AngleAxisd(angle, m.axis).toRotationMatrix();
  targets->points.resize(m.rest.rows(), 3);
  for (Index h = 0; h < m.rest.rows(); ++h) {
    Eigen::Vector3d p = m.rest.row(h).transpose();
    for (int w = 0; w < kModes; ++w)
      p += m.amp.row(w).transpose() * std::sin(m.wave.row(w).dot(m.rest.row(h)) + m.omega(w) * t + m.phase(w));
    targets->points.row(h) = (centroid + R * (p - centroid)).transpose();
  }
}

// ---------------------------------------------------------------- the run

struct Tally {
  long frames = 0, sets = 0, rejected = 0, least_squares_sets = 0, least_squares_frames = 0, plain_frames = 0;
  long violations = 0, set_violations = 0, energy_checks = 0;
  double set_max_ratio = 0.0;  // of the current handle set (--verbose)
  bool plain_rounds = false;   // --anderson 0: E′ is not computed (NaN) by design
  double max_energy = 0.0, max_ratio = 0.0, max_model_energy = 0.0;
  double rss_warm_kib = 0.0, rss_end_kib = 0.0, rss_max_kib = 0.0;
  std::vector<double> frame_seconds, set_seconds;
};

// Records a violation (printed for the first few).
void violation(Tally* tally, long frame, const std::string& what) {
  ++tally->set_violations;
  if (tally->violations++ < 20) std::fprintf(stderr, "soak: frame %ld: %s\n", frame, what.c_str());
}

double median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  std::nth_element(v.begin(), v.begin() + static_cast<long>(v.size() / 2), v.end());
  return v[v.size() / 2];
}

// Checks one frame's outcome against the rules at the top of this file.
void check_frame(long f, const FrameSummary& fs, const ConstraintSummary& cs, const Vertices& out,
                 const RotationElements& elements, const Vertices& rest, double e2, double gradient, double bound_factor,
                 bool classic, const SetMaker& maker, Tally* tally) {
  const bool ls_set = cs.status == Status::ConstraintsLeastSquares;
  if (!(fs.ok() || (ls_set && fs.status == Status::ConstraintsLeastSquares)))
    violation(tally, f, "frame status " + fs.brief_report());
  if (fs.status == Status::ConstraintsLeastSquares) ++tally->least_squares_frames;
  if (!out.allFinite()) return violation(tally, f, "NaN or infinity in the pose");
  if (std::isnan(fs.model_energy)) {
    ++tally->plain_frames;
    if (!tally->plain_rounds && fs.message.rfind("plain rounds:", 0) != 0)
      violation(tally, f, "E′ is NaN without a reason: " + fs.message);
  } else if (!std::isfinite(fs.model_energy)) {
    violation(tally, f, "E′ is infinite");
  } else {
    tally->max_model_energy = std::max(tally->max_model_energy, fs.model_energy);
  }
  const double reach = (out.rowwise() - maker.centroid().transpose()).rowwise().norm().maxCoeff();
  if (reach > kMaxReach * maker.diagonal())
    violation(tally, f, fmt::format("a vertex {:.3g} diagonals from the rest centroid", reach / maker.diagonal()));
  if (!classic) return;
  ++tally->energy_checks;
  const double e = arap_energy(rest, elements, out);
  if (!std::isfinite(e)) return violation(tally, f, "the ARAP energy of the pose is not finite");
  tally->max_energy = std::max(tally->max_energy, e);
  const double scale = gradient * gradient * e2;  // G²·E(2V): the field pose's energy
  tally->max_ratio = std::max(tally->max_ratio, e / scale);
  tally->set_max_ratio = std::max(tally->set_max_ratio, e / scale);
  if (e > bound_factor * scale)
    violation(tally, f, fmt::format("ARAP energy {:.6g} > {} × G²·E(2V) = {:.6g} (G = {:.3g})", e, bound_factor,
                                    bound_factor * scale, gradient));
}

std::string json_report(const Args& a, const std::string& label, const PrecomputeSummary& pre, const Tally& t,
                        double e2, double wall) {
  return fmt::format(
      "{{\n  \"model\": \"{}\",\n  \"vertices\": {},\n  \"seed\": {},\n  \"frames\": {},\n  \"set_every\": {},\n"
      "  \"handle_sets\": {},\n  \"rejected_sets\": {},\n  \"least_squares_sets\": {},\n"
      "  \"least_squares_frames\": {},\n  \"plain_round_frames\": {},\n"
      "  \"rss_warmup_kib\": {:.0f},\n  \"rss_end_kib\": {:.0f},\n  \"rss_max_kib\": {:.0f},\n"
      "  \"rss_growth_kib\": {:.0f},\n  \"rss_limit_kib\": {:.0f},\n"
      "  \"energy_checks\": {},\n  \"energy_scale_E2V\": {:.9g},\n  \"energy_bound_factor\": {},\n  \"max_energy\": {:.9g},\n"
      "  \"max_energy_over_G2_E2V\": {:.6g},\n  \"max_model_energy\": {:.9g},\n"
      "  \"frame_ms_median\": {:.6g},\n  \"set_handles_ms_median\": {:.6g},\n  \"precompute_s\": {:.4g},\n"
      "  \"wall_s\": {:.4g},\n  \"violations\": {}\n}}\n",
      label, pre.vertices, a.seed, t.frames, a.set_every, t.sets, t.rejected, t.least_squares_sets,
      t.least_squares_frames, t.plain_frames, t.rss_warm_kib, t.rss_end_kib, t.rss_max_kib,
      t.rss_end_kib - t.rss_warm_kib, a.rss_limit_kib, t.energy_checks, e2, a.energy_bound, t.max_energy, t.max_ratio,
      t.max_model_energy, 1e3 * median(t.frame_seconds), 1e3 * median(t.set_seconds), pre.total_seconds, wall,
      t.violations);
}

// --first-set: the sets before it are drawn (so the random stream is the
// same), not run.
void skip_first_sets(const Args& a, SetMaker* maker) {
  if (a.first_set > 0 && a.first_set % kInvalidEvery == kInvalidEvery - 1)
    usage(fmt::format("--first-set {} is an invalid handle set (every {}th); start one later", a.first_set, kInvalidEvery));
  for (long index = 0; index < a.first_set; ++index) {
    const SetKind kind = maker->kind_of(index, a.hostile);
    std::string what;
    if (kind == SetKind::Invalid && index > 0) maker->make_invalid(&what);
    else maker->motion(maker->make(kind == SetKind::Invalid ? SetKind::FewPoints : kind, index < 4, a.hostile));
  }
}

// The run's one-line verdict.
void print_summary(const Tally& tally, double seconds, bool rss_checked) {
  std::printf(
      "soak: %s: %ld frames, %ld handle sets (%ld invalid refused, %ld least-squares), wall %.1f s, frame median "
      "%.3f ms, set_handles median %.3f ms, RSS %.0f → %.0f KiB (%+.0f KiB after warm-up%s), max E/(G²E(2V)) %.3g, "
      "%ld violations\n",
      tally.violations ? "FAIL" : "ok", tally.frames, tally.sets, tally.rejected, tally.least_squares_sets, seconds,
      1e3 * median(tally.frame_seconds), 1e3 * median(tally.set_seconds), tally.rss_warm_kib, tally.rss_end_kib,
      tally.rss_end_kib - tally.rss_warm_kib, rss_checked ? "" : ", not checked: no frames after it",
      tally.max_ratio, tally.violations);
}

// Frame f starts a new handle set: an invalid one must be refused with a
// message; any other must be usable, and becomes *motion (its summary *cs).
void new_handle_set(Deformer& deformer, SetMaker& maker, const Args& a, long f, Tally* tally_out, Motion* motion,
                    ConstraintSummary* cs_out) {
  Tally& tally = *tally_out;
  ConstraintSummary& cs = *cs_out;
  const long index = f / a.set_every;
  const SetKind kind = maker.kind_of(index, a.hostile);
  ++tally.sets;
  if (kind == SetKind::Invalid && index > 0) {
    std::string what;
    const Handles bad = maker.make_invalid(&what);
    try {
      deformer.set_handles(bad);
      violation(&tally, f, "set_handles accepted an invalid handle set (" + what + ")");
    } catch (const std::invalid_argument& e) {
      ++tally.rejected;
      if (std::string(e.what()).empty()) violation(&tally, f, "an invalid handle set refused without a message");
    }
  } else {
    Motion next = maker.motion(maker.make(kind == SetKind::Invalid ? SetKind::FewPoints : kind, index < 4, a.hostile));
    const Timer t;
    cs = deformer.set_handles(next.handles);
    tally.set_seconds[static_cast<size_t>(tally.sets - tally.rejected - 1)] = t.seconds();
    if (!cs.usable()) violation(&tally, f, std::string(to_string(kind)) + " set refused: " + cs.brief_report());
    if (cs.status == Status::ConstraintsLeastSquares) ++tally.least_squares_sets;
    if (a.verbose)
      std::printf("set %ld at frame %ld: %s, %zu point handles, %s (rank %ld of %ld rows, condition %.3g)\n", index, f,
                  to_string(kind), next.handles.points.size(), cs.brief_report().c_str(),
                  static_cast<long>(cs.rank), static_cast<long>(cs.m), cs.condition);
    *motion = std::move(next);
  }
}

int run(const Args& a) {
  std::string label;
  const TriangleMesh mesh = load_model(a.model, &label);
  DeformableMesh model;
  model.V = mesh.V;
  model.F = mesh.F;
  Deformer deformer;
  DeformerOptions options;
  if (a.anderson >= 0) options.anderson_window = a.anderson;
  if (a.cold_start >= 0) options.cold_start_rounds = a.cold_start;  // 0: plain rounds, for an A/B
  if (a.rounds >= 1) options.iterations = a.rounds;
  const PrecomputeSummary pre = deformer.precompute(model, options);
  if (!pre.ok()) {
    std::fprintf(stderr, "soak: precompute failed: %s\n", pre.brief_report().c_str());
    return 1;
  }
  const RotationElements& elements = deformer.elements();
  const double e2 = arap_energy(model.V, elements, Vertices::Zero(model.V.rows(), 3));
  std::printf("soak: %s, %ld vertices, %ld frames, a new handle set every %ld (seed %llu)\n", label.c_str(),
              static_cast<long>(pre.vertices), a.frames, a.set_every, static_cast<unsigned long long>(a.seed));

  SetMaker maker(model.V, a.seed);
  Tally tally;
  tally.plain_rounds = options.anderson_window == 0;
  tally.frame_seconds.assign(static_cast<size_t>(a.frames), 0.0);  // touched now, not during the run
  tally.set_seconds.assign(static_cast<size_t>(a.frames / a.set_every + 1), 0.0);
  Vertices out(model.V.rows(), 3);
  HandleTargets targets;
  Motion motion;
  ConstraintSummary cs;
  const long warm_frames = std::min(a.frames, (a.first_set + a.warmup_sets) * a.set_every);
  // --random-rounds: a stream of its own (seed + 7), so that the sets are those of the run without it.
  std::mt19937 round_caps(static_cast<std::uint32_t>(a.seed) + 7u);
  const Timer wall;
  skip_first_sets(a, &maker);
  for (long f = a.first_set * a.set_every; f < a.frames; ++f) {
    if (f % a.set_every == 0) new_handle_set(deformer, maker, a, f, &tally, &motion, &cs);  // a new handle set
    targets_at(motion, maker.centroid(), &targets);
    ++motion.t;
    if (a.random_rounds > 0)
      deformer.set_rounds(std::uniform_int_distribution<int>(1, a.random_rounds)(round_caps), options.tolerance, 0.0);
    const FrameSummary fs = deformer.frame(targets, &out);
    tally.frame_seconds[static_cast<size_t>(f)] = fs.total_seconds;
    ++tally.frames;
    // The classic energy costs a few frames' time (an SVD per element): every
    // E-th frame, and the first and last of every handle set.
    const bool classic = f % a.energy_every == 0 || f % a.set_every == 0 || (f + 1) % a.set_every == 0;
    check_frame(f, fs, cs, out, elements, model.V, e2, motion.gradient, a.energy_bound, classic, maker, &tally);
    if (f / a.set_every == a.trace_set) {
      const double e = arap_energy(model.V, elements, out);
      std::printf("  frame %ld: E' %.6g, E/(G²E(2V)) %.4g, residual %.3g, rounds %d, rejected %d, %.3f ms\n", f,
                  fs.model_energy, e / (motion.gradient * motion.gradient * e2), fs.fixed_point_residual,
                  fs.iterations, fs.rejected_steps, 1e3 * fs.total_seconds);
    }
    if (f + 1 == warm_frames) tally.rss_warm_kib = resident_kib();
    if ((f + 1) % a.set_every == 0 || f + 1 == a.frames) {
      tally.rss_max_kib = std::max(tally.rss_max_kib, resident_kib());
      if (a.verbose) std::printf("  max E/(G²E(2V)) %.3g, %ld violations\n", tally.set_max_ratio, tally.set_violations);
      tally.set_max_ratio = 0.0, tally.set_violations = 0;
    }
  }
  const double seconds = wall.seconds();
  tally.set_seconds.resize(static_cast<size_t>(tally.sets - tally.rejected));
  tally.rss_end_kib = resident_kib();
  const bool rss_checked = warm_frames < a.frames;
  if (rss_checked && tally.rss_end_kib - tally.rss_warm_kib > a.rss_limit_kib)
    violation(&tally, a.frames, fmt::format("resident memory grew by {:.0f} KiB after the warm-up (limit {:.0f})",
                                            tally.rss_end_kib - tally.rss_warm_kib, a.rss_limit_kib));
  if (tally.rejected == 0 && tally.sets > kInvalidEvery)
    violation(&tally, a.frames, "no invalid handle set was tried");

  print_summary(tally, seconds, rss_checked);
  const std::string report = json_report(a, label, pre, tally, e2, seconds);
  if (a.json.empty()) {
    std::fputs(report.c_str(), stdout);
  } else {
    write_file_atomically(a.json, report);
  }
  return tally.violations ? 1 : 0;
}

}  // namespace

int main(int argc, char** argv) {
  qpreduce::restart_with_blas_core(argv);  // OpenBLAS's kernels for this CPU (cpu_features.h)
  const Args a = parse(argc, argv);
  try {
    return run(a);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "soak: %s\n", e.what());
    return 1;
  }
}
