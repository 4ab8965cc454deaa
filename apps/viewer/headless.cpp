#include "modes.h"

#include "reports.h"
#include "run_files.h"
#include "context.h"
#include "appearance.h"
#include "motion.h"

#include <qpreduce/deform/pipeline/run_scenario.h>
#include <qpreduce/util/timer.h>


#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cstdio>
#include <functional>
#include <stdexcept>

#include <unistd.h>

namespace qpr::viewer {

using namespace qpreduce;
using namespace qpreduce::deform;

namespace {

void stderr_progress(const std::string& stage, double fraction) {
  std::fprintf(stderr, "\r  precompute %3d%% %-20s", static_cast<int>(100 * fraction), stage.c_str());
  if (fraction >= 1.0) std::fprintf(stderr, "\n");
  std::fflush(stderr);
}

// What the frames of a headless run measured.
struct HeadlessRun {
  ScenarioRunSummary run;  // qpreduce::deform::run_scenario's
  ScenarioPoses poses;
  std::vector<double> iter_us, recon_ms, frame_ms;  // per frame
  double residual = 0.0;  // max handle residual / bbox diagonal
  double gpu_cpu = -1.0;  // GPU path: max |GPU read-back − CPU pose| / bbox diagonal after the last frame; −1 on the CPU path
};

// Plays the scenario's frames (or the recording's, --replay) through the
// library's run_scenario on the session's deformer: precompute, the on-site
// step, the frames (each reconstructed into the renderer's buffers, on the
// GPU or uploaded from the CPU pose, timed), then settle and refine with
// --refine. The session then holds the run's model, handles and last pose.
HeadlessRun run_frames(Session& session, MeshRenderer& renderer, const ViewerOptions& o) {
  HandleMotion motion;
  std::function<void(size_t)> pose;
  size_t frames = 0;
  if (!o.replay.empty()) {
    motion = read_motion(o.replay);
    handles_from_motion(motion, &session);
    frames = motion.frames.size();
    pose = [&](size_t f) { apply_motion_frame(motion, f, &session); };
  } else {
    session.handles_from_scenario();
    frames = session.scenario_frames();
    pose = [&](size_t f) { session.pose_scenario_frame(f); };
  }
  const Scenario played = session.played_scenario(session.input().options, frames, pose);

  ScenarioRunOptions options;
  options.deformer = session.input().options;
  options.refine = o.refine;
  ScenarioRunHooks hooks;
  if (isatty(fileno(stderr))) hooks.progress = stderr_progress;
  hooks.prepared = [&](const Deformer&, bool) { session.set_reconstruction(o.reconstruction, &renderer); };
  Deformer& deformer = *session.run_deformer();
  HeadlessRun out;
  hooks.frame = [&](int, const Vertices& V) {  // the frame into the renderer's buffers
    const Timer t;
    if (session.reconstruction() == Reconstruction::Gpu) {
      const auto& frame = deformer.normalization();
      renderer.reconstruct_gpu(deformer.reduced_coordinates(), (frame.scale * deformer.global_rotation()).cast<float>(),
                               frame.centre.cast<float>());
    } else {
      renderer.upload_positions(V);
    }
    glFinish();  // honest timing: wait for the GPU
    out.recon_ms.push_back(1e3 * t.seconds());
  };
  out.run = run_scenario(played, options, &deformer, &out.poses, hooks);
  if (!out.run.ok()) throw std::runtime_error(out.run.message);
  if (out.run.handles.status != Status::Success) std::fprintf(stderr, "  note: %s\n", out.run.handles.message.c_str());
  const bool gpu = session.reconstruction() == Reconstruction::Gpu;
  for (size_t f = 0; f < out.run.frames.size(); ++f) {
    const FrameSummary& fs = out.run.frames[f];
    out.iter_us.push_back(1e6 * fs.solve_seconds / std::max(1, fs.iterations));
    if (!gpu) out.recon_ms[f] += 1e3 * fs.reconstruct_seconds;  // the CPU pose, then its upload
    out.frame_ms.push_back(1e3 * (fs.total_seconds - fs.reconstruct_seconds) + out.recon_ms[f]);
    out.residual = std::max(out.residual, out.run.handle_residual[f]);
  }
  // GPU path: the read-back positions of the last frame against its CPU pose.
  if (gpu) {
    Vertices read;
    renderer.read_positions(&read);
    out.gpu_cpu = (read - out.poses.last).cwiseAbs().maxCoeff() / session.diagonal();
  }
  session.adopt_run(out.run.precompute, out.run.options, out.poses.last);
  if (out.run.refined) session.show_pose(out.poses.refined, &renderer);
  return out;
}

// Renders the last pose into the screenshot (and the mesh file when asked).
void write_last_frame(Session& session, MeshRenderer& renderer, RenderTarget& target, const ViewerOptions& o,
                      const SaveMeshFn& save_mesh) {
  renderer.set_colors(vertex_colors(o.color, session));
  if (o.show_handles) renderer.set_markers(0, handle_markers(session));
  Camera camera;
  Vertices last;
  session.positions(renderer, &last);
  set_camera(&camera, session.rest(), o, &last);
  MeshRenderer::Style style;
  style.mode = o.color;
  style.deviation_scale = o.deviation_scale * static_cast<float>(session.diagonal());
  style.marker_size = std::max(3.0f, o.height / 180.0f);
  target.bind();
  renderer.draw(camera, o.width, o.height, style);
  target.resolve();
  write_png(qpr::run_files().stage(o.screenshot), target.read_rgb());
  if (!o.out_mesh.empty()) {
    Vertices V;
    session.positions(renderer, &V);
    save_mesh(qpr::run_files().stage(o.out_mesh), V);
  }
}

void print_summary(const Session& session, const GlContext& context, const HeadlessRun& h, const ViewerOptions& o,
                   const nlohmann::json& refine) {
  const PrecomputeSummary& pre = h.run.precompute;
  const FrameSummary& last = h.run.frames.back();
  fmt::print("{}: {} vertices, {} linear / {} rotational proxies, {} patches; {} frames\n", session.input().name,
             pre.vertices, pre.linear_proxies, pre.rotational_proxies, pre.patches, h.run.frames.size());
  fmt::print("  renderer        {}\n", context.description());
  fmt::print("  reconstruction  {}{}\n", to_string(session.reconstruction()),
             session.gpu_unavailable_reason().empty() ? "" : " (GPU unavailable: " + session.gpu_unavailable_reason() + ")");
  fmt::print("  precompute {:.2f} s, OP {:.3f} ms, iteration {:.1f} µs, reconstruction {:.3f} ms, frame {:.3f} ms (medians)\n",
             pre.total_seconds, 1e3 * h.run.op_seconds, upper_median(h.iter_us), upper_median(h.recon_ms),
             upper_median(h.frame_ms));
  fmt::print("  handle residual {:.2e} (max, / bbox diagonal)", h.residual);
  if (h.gpu_cpu >= 0) fmt::print(", GPU vs CPU max |Δ| {:.2e} (/ bbox diagonal)", h.gpu_cpu);
  fmt::print("\n  fixed-point residual {:.2e} after {} rounds, ended by the {} (last frame)\n",
             last.fixed_point_residual, last.iterations, to_string(last.stop));
  if (!refine.is_null())
    fmt::print(
        "  refine {} rounds, {:.3f} s: ARAP energy {:.6g} -> {:.6g}, from the reduced pose RMS {:.2e}, max {:.2e} "
        "(/ bbox diagonal)\n",
        refine["rounds"].get<int>(), refine["seconds"].get<double>(), refine["initial_energy"].get<double>(),
        refine["arap_energy"].get<double>(), refine["rms_from_input"].get<double>(),
        refine["max_from_input"].get<double>());
  fmt::print("  wrote {}\n", o.screenshot);
}

nlohmann::json stats_json(const Session& session, const GlContext& context, const HeadlessRun& h,
                          const ViewerOptions& o, const nlohmann::json& refine) {
  const PrecomputeSummary& pre = h.run.precompute;
  const FrameSummary& last = h.run.frames.back();
  nlohmann::json j = {{"name", session.input().name},
                      {"renderer", context.description()},
                      {"reconstruction", session.reconstruction() == Reconstruction::Gpu ? "gpu" : "cpu"},
                      {"gpu_unavailable_reason", session.gpu_unavailable_reason()},
                      {"vertices", pre.vertices},
                      {"reduced_size", pre.reduced_size},
                      {"frames", h.run.frames.size()},
                      {"precompute_s", pre.total_seconds},
                      {"op_ms", 1e3 * h.run.op_seconds},
                      {"iteration_us", upper_median(h.iter_us)},
                      {"reconstruction_ms", upper_median(h.recon_ms)},
                      {"frame_ms", upper_median(h.frame_ms)},
                      {"handle_residual_max", h.residual},
                      {"gpu_cpu_max_deviation", h.gpu_cpu},
                      {"fixed_point_residual", last.fixed_point_residual},
                      {"rounds", last.iterations},
                      {"stop", to_string(last.stop)},
                      {"arap_energy", h.run.arap_energy},
                      {"screenshot", o.screenshot}};
  if (!refine.is_null()) j["refine"] = refine;
  j["run"] = to_json(h.run.report());  // every stage's summary (docs/formats.md, "Summaries")
  return j;
}

}  // namespace

int run_headless(Session& session, const ViewerOptions& o, const SaveMeshFn& save_mesh) {
  GlContext context(o.width, o.height, "qpr view", false);
  MeshRenderer renderer(session.rest(), session.input().faces);
  RenderTarget target;
  target.resize(o.width, o.height, o.samples);
  const HeadlessRun h = run_frames(session, renderer, o);
  const nlohmann::json refine = h.run.refined ? qpr::refine_json(h.run.refine, *o.refine) : nlohmann::json();
  write_last_frame(session, renderer, target, o, save_mesh);
  print_summary(session, context, h, o, refine);
  if (!o.stats_json.empty())
    write_json(qpr::run_files().stage(o.stats_json), stats_json(session, context, h, o, refine), "stats");
  return 0;
}

}  // namespace qpr::viewer
