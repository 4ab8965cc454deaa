#include "modes.h"

#include "app_support.h"
#include "run_files.h"
#include "context.h"
#include "view_support.h"


#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cstdio>
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
  size_t frames = 0;
  double op_ms = 0.0;
  std::vector<double> iter_us, recon_ms, frame_ms;
  double residual = 0.0;  // max handle residual / bbox diagonal
  double fixed_point_residual = 0.0;  // of the last frame (FrameSummary), after its `iterations` rounds
  int iterations = 0;
  qpreduce::RoundStop stop = qpreduce::RoundStop::RoundLimit;  // what ended the last frame's rounds
  double gpu_cpu = -1.0;  // GPU path: max |GPU read-back − CPU r₀·B·w| / bbox diagonal; −1 on the CPU path
};

// Sets the handles (from the recording, or the scenario's), the handle
// constraints, and runs every frame.
HeadlessRun run_frames(Session& session, MeshRenderer& renderer, const ViewerOptions& o) {
  HeadlessRun run;
  HandleMotion motion;
  if (!o.replay.empty()) {
    motion = read_motion(o.replay);
    handles_from_motion(motion, &session);
  } else {
    session.handles_from_scenario();
  }
  session.set_reconstruction(o.reconstruction, &renderer);
  std::string note;
  run.op_ms = session.update_constraints(&note);
  if (!note.empty()) std::fprintf(stderr, "  note: %s\n", note.c_str());

  run.frames = o.replay.empty() ? session.scenario_frames() : motion.frames.size();
  for (size_t f = 0; f < run.frames; ++f) {
    if (o.replay.empty()) session.pose_scenario_frame(f); else apply_motion_frame(motion, f, &session);
    const FrameStats s = session.step(&renderer);
    run.iter_us.push_back(s.iteration_us);
    run.recon_ms.push_back(s.reconstruction_ms);
    run.frame_ms.push_back(s.frame_ms);
    run.residual = std::max(run.residual, s.handle_residual);
    run.fixed_point_residual = s.fixed_point_residual;
    run.iterations = s.iterations;
    run.stop = s.stop;
  }
  // GPU path: compare the read-back positions with a CPU reconstruction of the same w.
  if (session.reconstruction() == Reconstruction::Gpu) {
    Vertices gpu;
    renderer.read_positions(&gpu);
    run.gpu_cpu = (gpu - session.cpu_reconstruction()).cwiseAbs().maxCoeff() / session.diagonal();
  }
  return run;
}

// Refines the last frame's pose on the session's worker (waiting for it: no
// user here), draws the refined pose, and returns the stats' "refine" object.
nlohmann::json refine_shown_pose(Session& session, MeshRenderer& renderer, const RefineOptions& options,
                                 Vertices* refined) {
  RefineWorker& worker = session.refine_worker(options);
  worker.start(session.handle_set(), session.targets(), session.last_pose());
  worker.wait_idle();
  const RefineStatus st = worker.status();
  if (st.state != RefineStatus::State::Done || !worker.poll(refined))
    throw std::runtime_error(fmt::format("refine {}: {}", to_string(st.state), st.message));
  session.show_pose(*refined, &renderer);
  return qpr::refine_json(st.summary, options);  // the keys of `qpr deform --refine`
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

void print_summary(const Session& session, const GlContext& context, const HeadlessRun& run, const ViewerOptions& o,
                   const nlohmann::json& refine) {
  const PrecomputeSummary& pre = session.summary();
  fmt::print("{}: {} vertices, {} linear / {} rotational proxies, {} patches; {} frames\n", session.input().name,
             pre.vertices, pre.linear_proxies, pre.rotational_proxies, pre.patches, run.frames);
  fmt::print("  renderer        {}\n", context.description());
  fmt::print("  reconstruction  {}{}\n", to_string(session.reconstruction()),
             session.gpu_unavailable_reason().empty() ? "" : " (GPU unavailable: " + session.gpu_unavailable_reason() + ")");
  fmt::print("  precompute {:.2f} s, OP {:.3f} ms, iteration {:.1f} µs, reconstruction {:.3f} ms, frame {:.3f} ms (medians)\n",
             pre.total_seconds, run.op_ms, upper_median(run.iter_us), upper_median(run.recon_ms),
             upper_median(run.frame_ms));
  fmt::print("  handle residual {:.2e} (max, / bbox diagonal)", run.residual);
  if (run.gpu_cpu >= 0) fmt::print(", GPU vs CPU max |Δ| {:.2e} (/ bbox diagonal)", run.gpu_cpu);
  fmt::print("\n  fixed-point residual {:.2e} after {} rounds, ended by the {} (last frame)\n",
             run.fixed_point_residual, run.iterations, to_string(run.stop));
  if (!refine.is_null())
    fmt::print(
        "  refine {} rounds, {:.3f} s: ARAP energy {:.6g} -> {:.6g}, from the reduced pose RMS {:.2e}, max {:.2e} "
        "(/ bbox diagonal)\n",
        refine["rounds"].get<int>(), refine["seconds"].get<double>(), refine["initial_energy"].get<double>(),
        refine["arap_energy"].get<double>(), refine["rms_from_input"].get<double>(),
        refine["max_from_input"].get<double>());
  fmt::print("  wrote {}\n", o.screenshot);
}

nlohmann::json stats_json(const Session& session, const GlContext& context, const HeadlessRun& run,
                          const ViewerOptions& o, const nlohmann::json& refine, double arap_energy) {
  const PrecomputeSummary& pre = session.summary();
  nlohmann::json j = {{"name", session.input().name},
                      {"renderer", context.description()},
                      {"reconstruction", session.reconstruction() == Reconstruction::Gpu ? "gpu" : "cpu"},
                      {"gpu_unavailable_reason", session.gpu_unavailable_reason()},
                      {"vertices", pre.vertices},
                      {"reduced_size", pre.reduced_size},
                      {"frames", run.frames},
                      {"precompute_s", pre.total_seconds},
                      {"op_ms", run.op_ms},
                      {"iteration_us", upper_median(run.iter_us)},
                      {"reconstruction_ms", upper_median(run.recon_ms)},
                      {"frame_ms", upper_median(run.frame_ms)},
                      {"handle_residual_max", run.residual},
                      {"gpu_cpu_max_deviation", run.gpu_cpu},
                      {"fixed_point_residual", run.fixed_point_residual},
                      {"iterations", run.iterations},
                      {"stop", to_string(run.stop)},
                      {"arap_energy", arap_energy},
                      {"screenshot", o.screenshot}};
  if (!refine.is_null()) j["refine"] = refine;
  return j;
}

}  // namespace

int run_headless(Session& session, const ViewerOptions& o, const SaveMeshFn& save_mesh) {
  GlContext context(o.width, o.height, "qpr view", false);
  MeshRenderer renderer(session.rest(), session.input().faces);
  RenderTarget target;
  target.resize(o.width, o.height, o.samples);
  session.precompute(session.input().options, isatty(fileno(stderr)) ? ProgressFn(stderr_progress) : ProgressFn());
  const HeadlessRun run = run_frames(session, renderer, o);
  Vertices shown;  // the pose drawn: the refined one with --refine
  const nlohmann::json refine = o.refine ? refine_shown_pose(session, renderer, *o.refine, &shown) : nlohmann::json();
  write_last_frame(session, renderer, target, o, save_mesh);
  print_summary(session, context, run, o, refine);
  if (!o.stats_json.empty()) {
    if (!o.refine) session.positions(renderer, &shown);
    write_json(qpr::run_files().stage(o.stats_json), stats_json(session, context, run, o, refine, session.arap_energy(shown)), "stats");
  }
  return 0;
}

}  // namespace qpr::viewer
