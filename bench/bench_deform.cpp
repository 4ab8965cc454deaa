// Benchmark: the paper's Table 1 on this machine — reduced ARAP deformation
// (Section 3.2) of the paper's models found in ../shared/data, with the
// paper's proxy counts (linear = farthest-point samples, rotational =
// spectral k-means clusters, both seeded).
//
// Per model <M>, benchmarks run in this order (one Deformer per model, made
// by the first of them that runs):
//   Precompute/<M>      clusters, proxies, energy, subspace, reduced matrices
//                       (one iteration, three repetitions: each a fresh
//                       precompute, so that table1.py can quote the median
//                       time on a shared machine; counters peak_MiB,
//                       extra_MiB per repetition)
//   OP/<M>              set_handles for 8 point handles (farthest-point
//                       vertices): the on-site preconditioner (counter
//                       fast_path: 1 when Phase 1's range-space path ran)
//   OPNullSpace/<M>     the same with ConstraintOptions::fast_path = false
//                       (Phase 1's null-space method), for an A/B
//   Iteration/<M>       one Phase 1 + Phase 2 round (a frame's alternation
//                       divided by its rounds; manual time)
//   IterationParallel/<M> the same with the rounds on all threads
//                       (DeformerOptions::round_threads = 0)
//   Reconstruction/<M>  V′ = r₀·(P·[N UD])·w over all vertices, as a frame
//                       runs it: after the frame's rounds (manual time)
//   ReconstructionVsRead/<M>
//                       the reconstruction, a plain parallel streaming read
//                       (Eigen's vectorised sum) of the reconstruction basis
//                       itself with the same threads, and the same read by
//                       an AVX2 loop (a stricter floor: this build is
//                       baseline x86-64), sampled alternately in one loop,
//                       each after a frame's rounds (counters recon_ms,
//                       read_ms, read_avx2_ms, ratio, ratio_avx2): the
//                       ratios the reconstruction target is judged by. After
//                       single-threaded rounds the second thread's vCPU has
//                       to be woken, which on a shared 2-vCPU machine costs
//                       tens of µs either way.
//   StreamRead/<M>, ReconstructionBackToBack/<M>
//                       the plain read and reconstruct_points one call after
//                       the other, outside any frame (the team kept busy)
//   Frame/<M>           a whole frame (8 rounds + reconstruction)
//   FrameDefault/<M>    a whole frame with the library's default rounds (to
//                       the tolerance within the time budget; counters
//                       rounds, budget_stops)
//   RefineRound/<M>     one round of the full-space finish (refine.h) from
//                       a frame's reduced pose, under the session's handles
//                       (single vertices: the per-axis factor), default
//                       options (Backend::Auto, all threads); manual time =
//                       the mean of rounds 2–5 of a 5-round refine, from
//                       RefineSummary::round_seconds (counters rounds,
//                       setup_ms, axis_separable)
//   RefineRoundSerial/<M>, RefineRoundCholmod/<M>
//                       the same on one thread, and with the per-axis
//                       factor by CHOLMOD (the A/B behind Backend::Auto)
// Every per-iteration benchmark also reports the median of its samples as
// the counter `median` (µs for Iteration, ms otherwise).
// With QPREDUCE_BENCH_CACHE_DIR set, the untimed sessions (all but
// Precompute) load the precomputed model from <dir>/<M>.qpr when it exists,
// and write it there otherwise.
// Frames move the first handle back and forth along a circle of radius 10%
// of the bounding-box diagonal; the others stay at rest (warm start).
//
// Models are looked up under $QPREDUCE_SHARED_DATA, else the source tree's
// ../shared/data; missing models are skipped with a message.
// bench/table1.py turns the JSON output into docs/performance.md's table.
#include "bench_util.h"
#include "deform_models.h"

#include <qpreduce/deform/deformer/deformer.h>
#include <qpreduce/deform/mesh/geometry.h>
#include <qpreduce/deform/io/mesh_io.h>
#include <qpreduce/deform/proxies/proxies.h>
#include <qpreduce/deform/io/tet_io.h>
#include <qpreduce/deform/refine/refine.h>
#include <qpreduce/point_reconstruction.h>

#include <qpreduce/util/cpu_features.h>
#include <qpreduce/util/timer.h>

#include <benchmark/benchmark.h>
#include <fmt/format.h>

#include <omp.h>

#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#endif

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <memory>
#include <string>
#include <vector>

namespace {

using namespace qpreduce;
using namespace qpreduce::deform;

using bench::kModels;
using bench::ModelSpec;

// Fresh precomputes per model (the Bumpy Plane's took 9.0–10.3 s over one
// session's single runs: quote the median, and the spread beside it).
constexpr int kPrecomputeRepetitions = 3;

struct Session {
  DeformableMesh model;
  DeformerOptions options;
  Deformer deformer;
  PrecomputeSummary pre;
  double peak_mib = 0.0, extra_mib = 0.0;
  Handles handles;
  Vertices rest_targets;
  double diagonal = 0.0;
  int frame = 0;
  Vertices out;
};

std::map<std::string, std::unique_ptr<Session>>& sessions() {
  static std::map<std::string, std::unique_ptr<Session>> s;
  return s;
}

// Loads the model and precomputes (timed by the caller when it wants).
Session& session(const ModelSpec& spec, benchmark::State* timed = nullptr) {
  auto& all = sessions();
  auto it = all.find(spec.name);
  if (it != all.end() && timed == nullptr) return *it->second;
  all.clear();  // one model in memory at a time: its peak is its own
  auto s = std::make_unique<Session>();
  s->model = bench::read_model(spec, &s->options);
  bench::PeakMemory mem;
  mem.reset();
  if (timed) {
    for (auto _ : *timed) s->pre = s->deformer.precompute(s->model, s->options);
    if (!s->pre.ok()) throw std::runtime_error(spec.name + std::string(": ") + s->pre.message);
  } else {
    // Untimed sessions may come from a cache (QPREDUCE_BENCH_CACHE_DIR, for
    // profiling the per-frame parts without paying for precompute each run).
    s->pre = bench::load_or_precompute(spec, s->model, s->options, bench::cache_path(spec), &s->deformer);
  }
  s->peak_mib = mem.peak_mb();
  s->extra_mib = s->peak_mib - mem.baseline_mb();
  s->handles = bench::spread_handles(s->model, &s->rest_targets);
  s->diagonal = bounding_box_diagonal(s->model.V);
  const ConstraintSummary cs = s->deformer.set_handles(s->handles);
  if (!cs.usable()) throw std::runtime_error(spec.name + std::string(": handles: ") + cs.message);
  Session& ref = *s;
  all[spec.name] = std::move(s);
  return ref;
}

HandleTargets next_targets(Session& s) { return bench::moved_targets(s.rest_targets, s.diagonal, s.frame++); }

void set_sizes(benchmark::State& state, const Session& s) {
  state.counters["vertices"] = static_cast<double>(s.pre.vertices);
  state.counters["linear"] = static_cast<double>(s.pre.linear_proxies);
  state.counters["rotational"] = static_cast<double>(s.pre.rotational_proxies);
  state.counters["reduced"] = static_cast<double>(s.pre.reduced_size);
}

void BM_Precompute(benchmark::State& state, const ModelSpec* spec) {
  try {
    Session& s = session(*spec, &state);
    set_sizes(state, s);
    state.counters["peak_MiB"] = s.peak_mib;
    state.counters["extra_MiB"] = s.extra_mib;
    state.counters["subspace_s"] = s.pre.subspace_seconds;
    state.counters["clustering_s"] = s.pre.clustering_seconds;
  } catch (const std::exception& e) {
    state.SkipWithError(e.what());
  }
}

// Median of per-iteration samples, as a counter (the reported time is the
// mean; on a shared machine the median is the steadier figure).
void set_median(benchmark::State& state, std::vector<double> samples, double unit) {
  if (samples.empty()) return;
  std::nth_element(samples.begin(), samples.begin() + samples.size() / 2, samples.end());
  state.counters["median"] = samples[samples.size() / 2] / unit;
}

// fast_path = false: the null-space method for Phase 1 and F_y formed in
// full (ConstraintOptions::fast_path), for an A/B in the same run.
void BM_OP(benchmark::State& state, const ModelSpec* spec, bool fast_path) {
  Session& s = session(*spec);
  ConstraintOptions options;
  options.fast_path = fast_path;
  std::vector<double> samples;
  bool fast = false;
  for (auto _ : state) {
    const qpreduce::Timer t;
    const ConstraintSummary cs = s.deformer.set_handles(s.handles, options);
    samples.push_back(t.seconds());
    fast = cs.fast_path;
    benchmark::DoNotOptimize(cs.rank);
  }
  state.counters["fast_path"] = fast ? 1.0 : 0.0;
  set_median(state, std::move(samples), 1e-3);
  set_sizes(state, s);
}

// Runs frames; reports the chosen part of each as the iteration's time.
enum class Part { Iteration, Reconstruction, Frame };

// threads: DeformerOptions::round_threads for these frames (0: all);
// window: DeformerOptions::anderson_window for these frames (−1: the
// default), so that accelerated and plain rounds are timed in one session.
void BM_FramePart(benchmark::State& state, const ModelSpec* spec, Part part, int threads, int window) {
  Session& s = session(*spec);
  s.deformer.set_round_threads(threads);
  if (window >= 0) s.deformer.set_anderson_window(window);
  std::vector<double> samples;
  for (auto _ : state) {
    const HandleTargets t = next_targets(s);
    // The Iteration part skips reconstruction (frame(targets, nullptr)):
    // with manual time, min_time counts rounds only, and thousands of frames
    // with a full reconstruction each would take minutes on a large mesh.
    const FrameSummary f = s.deformer.frame(t, part == Part::Iteration ? nullptr : &s.out);
    const double seconds = part == Part::Iteration        ? f.solve_seconds / std::max(f.iterations, 1)
                           : part == Part::Reconstruction ? f.reconstruct_seconds
                                                          : f.total_seconds;
    state.SetIterationTime(seconds);
    samples.push_back(seconds);
  }
  s.deformer.set_round_threads(1);
  s.deformer.set_anderson_window(s.options.anderson_window);
  set_median(state, std::move(samples), part == Part::Iteration ? 1e-6 : 1e-3);
  set_sizes(state, s);
}

// Frames with the library's default rounds (to DeformerOptions' tolerance
// within its time budget; docs/deform.md, "Rounds per frame") instead of
// Table 1's 8, with the reconstruction: counters rounds (median) and
// budget_stops (the fraction of frames the budget ended).
void BM_FrameDefault(benchmark::State& state, const ModelSpec* spec) {
  Session& s = session(*spec);
  const DeformerOptions defaults;
  s.deformer.set_rounds(defaults.iterations, defaults.tolerance, defaults.time_budget);
  std::vector<double> samples, rounds;
  int budget_stops = 0;
  for (auto _ : state) {
    const FrameSummary f = s.deformer.frame(next_targets(s), &s.out);
    state.SetIterationTime(f.total_seconds);
    samples.push_back(f.total_seconds);
    rounds.push_back(f.iterations);
    budget_stops += f.stop == RoundStop::TimeBudget ? 1 : 0;
  }
  s.deformer.set_rounds(s.options.iterations, s.options.tolerance, s.options.time_budget);
  if (!rounds.empty()) {
    std::nth_element(rounds.begin(), rounds.begin() + rounds.size() / 2, rounds.end());
    state.counters["rounds"] = rounds[rounds.size() / 2];
    state.counters["budget_stops"] = static_cast<double>(budget_stops) / static_cast<double>(rounds.size());
  }
  set_median(state, std::move(samples), 1e-3);
  set_sizes(state, s);
}

// The reconstruction basis B itself, read once: each thread sums its share
// of the rows (the same threads and the same bytes as reconstruction, without
// the products), with Eigen's vectorised reduction — SSE2 in this build,
// compiled for baseline x86-64 like the library — or, for a stricter floor,
// an AVX2 loop with four accumulators.
float sum_eigen(const float* x, Index n) { return Eigen::Map<const Eigen::VectorXf>(x, n).sum(); }

#if defined(__x86_64__) && defined(__GNUC__)
#define BENCH_HAVE_AVX2 1
__attribute__((target("avx2"))) float sum_avx2(const float* x, Index n) {
  __m256 a0 = _mm256_setzero_ps(), a1 = a0, a2 = a0, a3 = a0;
  Index i = 0;
  for (; i + 32 <= n; i += 32) {
    a0 = _mm256_add_ps(a0, _mm256_loadu_ps(x + i));
    a1 = _mm256_add_ps(a1, _mm256_loadu_ps(x + i + 8));
    a2 = _mm256_add_ps(a2, _mm256_loadu_ps(x + i + 16));
    a3 = _mm256_add_ps(a3, _mm256_loadu_ps(x + i + 24));
  }
  alignas(32) float lanes[8];
  _mm256_store_ps(lanes, _mm256_add_ps(_mm256_add_ps(a0, a1), _mm256_add_ps(a2, a3)));
  float total = 0.0f;
  for (float l : lanes) total += l;
  for (; i < n; ++i) total += x[i];
  return total;
}
#endif

using SumFn = float (*)(const float*, Index);

float stream_read(const RowMatrixXf& basis, SumFn sum) {
  const Index rows = basis.rows(), cols = basis.cols();
  float total = 0.0f;
#pragma omp parallel reduction(+ : total)
  {
    const int threads = omp_get_num_threads(), me = omp_get_thread_num();
    const Index r0 = rows * me / threads, r1 = rows * (me + 1) / threads;
    total += sum(basis.data() + r0 * cols, (r1 - r0) * cols);
  }
  return total;
}

void BM_StreamRead(benchmark::State& state, const ModelSpec* spec) {
  Session& s = session(*spec);
  const auto& basis = s.deformer.reconstruction_basis();
  std::vector<double> samples;
  for (auto _ : state) {
    const qpreduce::Timer t;
    benchmark::DoNotOptimize(stream_read(basis, sum_eigen));
    const double seconds = t.seconds();
    state.SetIterationTime(seconds);
    samples.push_back(seconds);
  }
  const double bytes = static_cast<double>(basis.size()) * sizeof(float);
  state.SetBytesProcessed(static_cast<int64_t>(static_cast<double>(state.iterations()) * bytes));
  state.counters["MiB"] = bytes / (1024.0 * 1024.0);
  set_median(state, std::move(samples), 1e-3);
  set_sizes(state, s);
}

// reconstruct_points on the last frame's coordinates, back to back: the
// reconstruction without the frame around it.
void BM_ReconstructionBackToBack(benchmark::State& state, const ModelSpec* spec) {
  Session& s = session(*spec);
  s.deformer.frame(next_targets(s), nullptr);
  const Eigen::Matrix3f r0 = s.deformer.global_rotation().cast<float>();
  std::vector<double> samples;
  for (auto _ : state) {
    const qpreduce::Timer t;
    reconstruct_points(s.deformer.reconstruction_basis(), s.deformer.reduced_coordinates(), r0, &s.out,
                       s.deformer.normalization().scale, s.deformer.normalization().centre);
    const double seconds = t.seconds();
    state.SetIterationTime(seconds);
    samples.push_back(seconds);
  }
  set_median(state, std::move(samples), 1e-3);
  set_sizes(state, s);
}

// Reconstruction and the streaming reads sampled alternately, each after a
// frame's rounds: every iteration runs three frames, times the first one's
// reconstruction, then the plain read after the second's rounds and the AVX2
// read after the third's. A burst of load from another tenant of the machine
// then falls on all three series alike. Counters: the medians (ms) and the
// ratios of the medians; the benchmark's own time is the reconstruction.
void BM_ReconstructionVsRead(benchmark::State& state, const ModelSpec* spec) {
  Session& s = session(*spec);
  const auto& basis = s.deformer.reconstruction_basis();
  std::vector<double> recon, plain, avx2;
  for (auto _ : state) {
    const FrameSummary f = s.deformer.frame(next_targets(s), &s.out);
    state.SetIterationTime(f.reconstruct_seconds);
    recon.push_back(f.reconstruct_seconds);
    s.deformer.frame(next_targets(s), nullptr);
    qpreduce::Timer t;
    benchmark::DoNotOptimize(stream_read(basis, sum_eigen));
    plain.push_back(t.seconds());
#ifdef BENCH_HAVE_AVX2
    if (__builtin_cpu_supports("avx2")) {
      s.deformer.frame(next_targets(s), nullptr);
      t.reset();
      benchmark::DoNotOptimize(stream_read(basis, sum_avx2));
      avx2.push_back(t.seconds());
    }
#endif
  }
  auto median_ms = [](std::vector<double> v) {
    if (v.empty()) return std::nan("");
    std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
    return 1e3 * v[v.size() / 2];
  };
  const double r = median_ms(recon), p = median_ms(plain), a = median_ms(avx2);
  state.counters["recon_ms"] = r;
  state.counters["read_ms"] = p;
  state.counters["read_avx2_ms"] = a;
  state.counters["ratio"] = r / p;
  state.counters["ratio_avx2"] = r / a;
  set_sizes(state, s);
}

void BM_RefineRound(benchmark::State& state, const ModelSpec* spec, Backend backend, int threads) {
  Session& s = session(*spec);
  const HandleTargets targets = next_targets(s);
  Vertices reduced;
  s.deformer.frame(targets, &reduced);
  RefineOptions options;
  options.backend = backend;
  options.threads = threads;
  options.tolerance = 0.0;     // no early stop: every call runs its rounds
  options.max_iterations = 5;  // timed: rounds 2–5 (the first includes the call's set-up)
  Refiner refiner;
  refiner.precompute(s.model, options);
  Vertices out;
  const RefineSummary first = refiner.refine(s.handles, targets, reduced, &out);  // factors
  if (!first.ok()) {
    state.SkipWithError(first.message.c_str());
    return;
  }
  int rounds = 0;
  for (auto _ : state) {
    const RefineSummary r = refiner.refine(s.handles, targets, reduced, &out);
    if (r.round_seconds.size() < 2) {
      state.SkipWithError("the refine stopped after one round");
      return;
    }
    state.SetIterationTime((r.round_seconds.back() - r.round_seconds.front()) /
                           static_cast<double>(r.round_seconds.size() - 1));
    rounds += static_cast<int>(r.round_seconds.size()) - 1;
  }
  state.counters["rounds"] = rounds;
  state.counters["setup_ms"] = 1e3 * first.setup_seconds;
  state.counters["axis_separable"] = first.axis_separable ? 1 : 0;
  set_sizes(state, s);
}

}  // namespace

int main(int argc, char** argv) {
  qpreduce::restart_with_blas_core(argv);  // OpenBLAS's kernels for this CPU (cpu_features.h)
  benchmark::Initialize(&argc, argv);
  // The BLAS kernels behind OP and the precompute (qpreduce/util/cpu_features.h).
  benchmark::AddCustomContext("blas_core", qpreduce::blas_core());
  const std::string dir = bench::shared_data_dir();
  int found = 0;
  for (const ModelSpec& spec : kModels) {
    if (!std::filesystem::exists(dir + "/" + spec.path)) {
      fmt::print(stderr, "bench_deform: skipping {} ({} not found)\n", spec.name, dir + "/" + spec.path);
      continue;
    }
    ++found;
    const std::string n = spec.name;
    benchmark::RegisterBenchmark(("Precompute/" + n).c_str(), BM_Precompute, &spec)
        ->Iterations(1)
        ->Repetitions(kPrecomputeRepetitions)
        ->Unit(benchmark::kSecond)
        ->UseRealTime();
    benchmark::RegisterBenchmark(("OP/" + n).c_str(), BM_OP, &spec, true)->Unit(benchmark::kMillisecond)->UseRealTime();
    benchmark::RegisterBenchmark(("OPNullSpace/" + n).c_str(), BM_OP, &spec, false)
        ->Unit(benchmark::kMillisecond)
        ->UseRealTime();
    benchmark::RegisterBenchmark(("Iteration/" + n).c_str(), BM_FramePart, &spec, Part::Iteration, 1, -1)
        ->Unit(benchmark::kMicrosecond)
        ->UseManualTime();
    benchmark::RegisterBenchmark(("IterationParallel/" + n).c_str(), BM_FramePart, &spec, Part::Iteration, 0, -1)
        ->Unit(benchmark::kMicrosecond)
        ->UseManualTime();
    benchmark::RegisterBenchmark(("Reconstruction/" + n).c_str(), BM_FramePart, &spec, Part::Reconstruction, 1, -1)
        ->Unit(benchmark::kMillisecond)
        ->UseManualTime();
    benchmark::RegisterBenchmark(("ReconstructionVsRead/" + n).c_str(), BM_ReconstructionVsRead, &spec)
        ->Unit(benchmark::kMillisecond)
        ->UseManualTime();
    benchmark::RegisterBenchmark(("StreamRead/" + n).c_str(), BM_StreamRead, &spec)
        ->Unit(benchmark::kMillisecond)
        ->UseManualTime();
    benchmark::RegisterBenchmark(("ReconstructionBackToBack/" + n).c_str(), BM_ReconstructionBackToBack, &spec)
        ->Unit(benchmark::kMillisecond)
        ->UseManualTime();
    benchmark::RegisterBenchmark(("Frame/" + n).c_str(), BM_FramePart, &spec, Part::Frame, 1, -1)
        ->Unit(benchmark::kMillisecond)
        ->UseManualTime();
    benchmark::RegisterBenchmark(("FrameDefault/" + n).c_str(), BM_FrameDefault, &spec)
        ->Unit(benchmark::kMillisecond)
        ->UseManualTime();
    // The same frames with plain rounds (anderson_window 0: the rounds of
    // the paper's step cost the same), for the default's frame-time ratio.
    benchmark::RegisterBenchmark(("FramePlain/" + n).c_str(), BM_FramePart, &spec, Part::Frame, 1, 0)
        ->Unit(benchmark::kMillisecond)
        ->UseManualTime();
    benchmark::RegisterBenchmark(("IterationPlain/" + n).c_str(), BM_FramePart, &spec, Part::Iteration, 1, 0)
        ->Unit(benchmark::kMicrosecond)
        ->UseManualTime();
    benchmark::RegisterBenchmark(("RefineRound/" + n).c_str(), BM_RefineRound, &spec, Backend::Auto, 0)
        ->Unit(benchmark::kMillisecond)
        ->UseManualTime();
    benchmark::RegisterBenchmark(("RefineRoundSerial/" + n).c_str(), BM_RefineRound, &spec, Backend::Auto, 1)
        ->Unit(benchmark::kMillisecond)
        ->UseManualTime();
    benchmark::RegisterBenchmark(("RefineRoundCholmod/" + n).c_str(), BM_RefineRound, &spec, Backend::Cholmod, 0)
        ->Unit(benchmark::kMillisecond)
        ->UseManualTime();
  }
  if (found == 0) fmt::print(stderr, "bench_deform: no model found under {} (set QPREDUCE_SHARED_DATA)\n", dir);
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
