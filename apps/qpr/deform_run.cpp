#include "deform_run.h"

#include <qpreduce/deform/geometry.h>
#include <qpreduce/deform/mesh_io.h>
#include <qpreduce/deform/tet_io.h>
#include <qpreduce/detail/timer.h>

#include <fmt/format.h>
#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <fstream>
#include <stdexcept>

namespace qpr {

using namespace qpreduce;
using namespace qpreduce::deform;

double peak_rss_mb() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  return static_cast<double>(usage.ru_maxrss) / 1024.0;  // ru_maxrss is in KiB on Linux
}

namespace {

double median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  const size_t h = v.size() / 2;
  return v.size() % 2 ? v[h] : 0.5 * (v[h - 1] + v[h]);
}

std::string frame_path(const std::string& pattern, int frame, bool many) {
  const auto pos = pattern.find("{frame}");
  if (pos != std::string::npos) {
    std::string s = pattern;
    s.replace(pos, 7, fmt::format("{:03d}", frame));
    return s;
  }
  if (!many) return pattern;
  const auto dot = pattern.find_last_of('.');
  return dot == std::string::npos ? fmt::format("{}_{:03d}", pattern, frame)
                                  : fmt::format("{}_{:03d}{}", pattern.substr(0, dot), frame, pattern.substr(dot));
}

void write_pose(const std::string& path, const Vertices& V, const TriangleMesh* surface, const TetMesh* solid) {
  if (surface) {
    write_triangle_mesh(path, TriangleMesh{V, surface->F});
    return;
  }
  const std::string ext = path.substr(path.find_last_of('.') + 1);
  if (ext == "mesh" || ext == "node" || ext == "ele") {
    write_tet_mesh(path, TetMesh{V, solid->T, solid->F});
  } else if (solid->F.rows() > 0) {
    write_triangle_mesh(path, TriangleMesh{V, solid->F});  // the boundary surface
  } else {
    throw std::invalid_argument(path + ": this tet mesh has no boundary triangles; write a .mesh instead");
  }
}

void progress_bar(const std::string& stage, double fraction) {
  const int width = 30, filled = static_cast<int>(fraction * width + 0.5);
  std::fprintf(stderr, "\r  precompute [%s%s] %3d%% %-16s", std::string(static_cast<size_t>(filled), '#').c_str(),
               std::string(static_cast<size_t>(width - filled), ' ').c_str(), static_cast<int>(100 * fraction),
               stage.c_str());
  if (fraction >= 1.0) std::fprintf(stderr, "\n");
  std::fflush(stderr);
}

}  // namespace

nlohmann::json run_scenario(const Scenario& scenario, const TriangleMesh* surface, const TetMesh* solid,
                            const RunSettings& settings) {
  DeformerOptions options = settings.options;
  if (scenario.alpha) options.energy.alpha = *scenario.alpha;
  if (scenario.beta) options.energy.beta = *scenario.beta;
  if (scenario.iterations) options.iterations = *scenario.iterations;

  Deformer deformer;
  const bool tty = isatty(fileno(stderr)) != 0;
  const ProgressFn progress = settings.progress && tty ? ProgressFn(progress_bar) : ProgressFn();
  const PrecomputeSummary pre = deformer.precompute(scenario.model, options, progress);
  if (!pre.ok()) throw std::runtime_error("precompute failed: " + pre.message);
  const double peak_mb = peak_rss_mb();

  const detail::Timer op_timer;
  const ConstraintSummary cs = deformer.set_handles(scenario.handles, scenario.constraints);
  const double op_ms = 1e3 * op_timer.seconds();
  if (!usable(cs.status)) throw std::runtime_error("handles: " + cs.message);
  if (cs.status != Status::Success) std::fprintf(stderr, "  note: %s\n", cs.message.c_str());

  const double diag = bounding_box_diagonal(scenario.model.V);
  const int frames = static_cast<int>(scenario.frames.size());
  std::vector<double> iter_us, recon_ms, frame_ms, residual;
  Vertices out;
  for (int f = 0; f < frames; ++f) {
    const FrameSummary fs = deformer.frame(scenario.frames[f], &out);
    iter_us.push_back(1e6 * fs.solve_seconds / std::max(1, fs.iterations));
    recon_ms.push_back(1e3 * fs.reconstruct_seconds);
    frame_ms.push_back(1e3 * fs.total_seconds);
    residual.push_back(handle_residual(scenario, scenario.frames[f], out) / diag);
    const bool write = std::find(settings.write_frames.begin(), settings.write_frames.end(), f) !=
                           settings.write_frames.end() ||
                       (f == frames - 1 && std::find(settings.write_frames.begin(), settings.write_frames.end(), -1) !=
                                               settings.write_frames.end());
    if (write && !settings.out_path.empty())
      write_pose(frame_path(settings.out_path, f, settings.write_frames.size() > 1), out, surface, solid);
  }
  const double energy = arap_energy(scenario.model.V, deformer.elements(), out);

  nlohmann::json report;
  report["name"] = settings.name;
  report["vertices"] = pre.vertices;
  report["elements"] = pre.elements;
  report["mesh_type"] = scenario.model.is_tet() ? "tet" : "triangle";
  report["linear_proxies"] = pre.linear_proxies;
  report["rotational_proxies"] = pre.rotational_proxies;
  report["patches"] = pre.patches;
  report["reduced_size"] = pre.reduced_size;
  report["frames"] = frames;
  report["iterations"] = options.iterations;
  report["alpha"] = options.energy.alpha;
  report["beta"] = options.energy.beta;
  report["precompute_s"] = pre.total_seconds;
  report["precompute_breakdown_s"] = {{"clustering", pre.clustering_seconds},
                                      {"assembly", pre.assembly_seconds},
                                      {"subspace", pre.subspace_seconds},
                                      {"reduction", pre.reduction_seconds}};
  report["precompute_peak_mb"] = peak_mb;
  report["subspace_backend"] = to_string(pre.subspace.backend_used);
  report["kkt_residual"] = pre.subspace.kkt_residual;
  report["op_ms"] = op_ms;
  report["op_status"] = to_string(cs.status);
  report["iteration_us"] = median(iter_us);
  report["reconstruction_ms"] = median(recon_ms);
  report["frame_ms"] = median(frame_ms);
  report["handle_residual_max"] = *std::max_element(residual.begin(), residual.end());
  report["arap_energy"] = energy;
  report["bounding_box_diagonal"] = diag;

  fmt::print("{}: {} vertices, {} {} elements, {} linear / {} rotational proxies, {} patches\n", settings.name,
             pre.vertices, pre.elements, scenario.model.is_tet() ? "tet" : "rotation", pre.linear_proxies,
             pre.rotational_proxies, pre.patches);
  fmt::print("  {:<28}{:>12.3f} s   (peak RSS {:.0f} MB, backend {})\n", "precompute", pre.total_seconds, peak_mb,
             to_string(pre.subspace.backend_used));
  fmt::print("  {:<28}{:>12.3f} ms\n", "OP (set handles)", op_ms);
  fmt::print("  {:<28}{:>12.2f} µs   (median over {} frames, {} iterations each)\n", "one iteration", median(iter_us),
             frames, options.iterations);
  fmt::print("  {:<28}{:>12.3f} ms\n", "reconstruction", median(recon_ms));
  fmt::print("  {:<28}{:>12.3f} ms\n", "frame total", median(frame_ms));
  fmt::print("  {:<28}{:>12.2e}      (max over frames, / bbox diagonal)\n", "handle residual", report["handle_residual_max"].get<double>());
  fmt::print("  {:<28}{:>12.5g}      (last frame)\n", "ARAP energy", energy);
  if (!settings.report_path.empty()) {
    std::ofstream f(settings.report_path);
    if (!f) throw std::runtime_error(settings.report_path + ": cannot write the report");
    f << report.dump(2) << "\n";
  }
  return report;
}

}  // namespace qpr
