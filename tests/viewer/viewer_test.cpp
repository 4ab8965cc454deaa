// The viewer's GL paths, run headless (ctest runs this under `xvfb-run -a`):
// GPU reconstruction (basis in a texture buffer, transform feedback) against
// the Deformer's own CPU reconstruction, a scripted drag that must change the
// picture, recorded motion round trips, bad input, and the window's writers
// (recordings, screenshots) on a full device, a missing directory and a
// file-size limit.
#include <camera.h>
#include <context.h>
#include <image.h>
#include <motion.h>
#include <refine_worker.h>
#include <renderer.h>
#include <session.h>

#include <qpreduce/deform/mesh/geometry.h>
#include <qpreduce/deform/mesh/shapes.h>
#include <qpreduce/deform/mesh/tet_boundary.h>
#include <qpreduce/deform/pipeline/run_scenario.h>

#include "../file_size_limit.h"

#include <Eigen/Geometry>
#include <catch2/catch.hpp>

#include <cfloat>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <memory>
#include <mutex>
#include <sstream>
#include <string>

#include <unistd.h>

using namespace qpreduce;
using namespace qpreduce::deform;
using namespace qpr::viewer;

namespace {

constexpr int kSize = 160;
constexpr Index kAround = 16, kRings = 12;

ViewerInput cylinder_input() {
  const TriangleMesh mesh = shapes::capped_cylinder(0.5, 4.0, kAround, kRings);
  ViewerInput in;
  in.scenario.model.V = mesh.V;
  in.scenario.model.F = mesh.F;
  in.faces = mesh.F;
  in.options.linear_proxies = 10;
  in.options.rotational_proxies = 8;
  in.options.iterations = 4;
  in.options.time_budget = 0.0;  // the same rounds in every session, however slow the build
  in.name = "cylinder";
  return in;
}

std::vector<int> ring(Index j) {
  std::vector<int> r;
  for (Index v = 0; v < kAround; ++v) r.push_back(static_cast<int>(j * kAround + v));
  return r;
}

// Bottom ring held, top ring dragged sideways and twisted, in `steps` frames.
void scripted_drag(Session* s, MeshRenderer* renderer, int steps, std::vector<FrameStats>* stats) {
  s->add_handle(ring(0), "base");
  s->add_handle(ring(kRings - 1), "top");
  for (int k = 1; k <= steps; ++k) {
    const double t = static_cast<double>(k) / steps;
    Eigen::Affine3d T = Eigen::Translation3d(1.5 * t, 0.0, -0.3 * t) * Eigen::Translation3d(0, 0, 4.0) *
                        Eigen::AngleAxisd(0.8 * t, Eigen::Vector3d::UnitZ()) * Eigen::Translation3d(0, 0, -4.0);
    s->handles()[1].transform = T.matrix();
    stats->push_back(s->step(renderer));
  }
}

// One GL context for the whole run: a second one, opened after the first is
// closed, can find xvfb-run's server resetting (its last client left).
const GlContext& gl_context() {
  static const GlContext context(kSize, kSize, "viewer_test", false);
  return context;
}

// Holds a refine inside one round (the first time the worker's hook sees
// `round` rounds done) until release(): the test then acts while the worker
// is provably busy, without timing.
class RoundLatch {
 public:
  explicit RoundLatch(int round) : round_(round) {}
  RefineWorker::RoundHook hook() {
    return [this](int rounds) {
      std::unique_lock<std::mutex> lock(m_);
      if (rounds != round_ || reached_) return;
      reached_ = inside_ = true;
      cv_.notify_all();
      cv_.wait(lock, [this] { return released_; });
      inside_ = false;
    };
  }
  // Waits until the worker is held, or is no longer running; true when held.
  bool wait_held(const RefineWorker& worker) {
    std::unique_lock<std::mutex> lock(m_);
    while (!reached_ && worker.status().state == RefineStatus::State::Running)
      cv_.wait_for(lock, std::chrono::milliseconds(10));
    return reached_;
  }
  bool inside() {
    std::lock_guard<std::mutex> lock(m_);
    return inside_;
  }
  void release() {
    {
      std::lock_guard<std::mutex> lock(m_);
      released_ = true;
    }
    cv_.notify_all();
  }

 private:
  const int round_;
  std::mutex m_;
  std::condition_variable cv_;
  bool reached_ = false, inside_ = false, released_ = false;
};

Image render(const MeshRenderer& renderer, RenderTarget* target, const Vertices& rest) {
  Camera camera;
  camera.up_axis = 2;
  camera.fit(rest.colwise().minCoeff().cast<float>().transpose() - Eigen::Vector3f(1.5f, 1.5f, 0.5f),
             rest.colwise().maxCoeff().cast<float>().transpose() + Eigen::Vector3f(1.5f, 1.5f, 0.5f));
  camera.pitch = 0.2f;
  target->bind();
  renderer.draw(camera, kSize, kSize, MeshRenderer::Style{});
  target->resolve();
  return target->read_rgb();
}

}  // namespace

TEST_CASE("headless GL: GPU reconstruction matches the CPU one, and a drag changes the picture") {
  INFO(gl_context().description());
  RenderTarget target;
  target.resize(kSize, kSize, 4);

  Session gpu_session(cylinder_input()), cpu_session(cylinder_input());
  gpu_session.precompute(gpu_session.input().options);
  cpu_session.precompute(cpu_session.input().options);
  MeshRenderer gpu_renderer(gpu_session.rest(), gpu_session.input().faces);
  MeshRenderer cpu_renderer(cpu_session.rest(), cpu_session.input().faces);

  const Image rest_image = render(gpu_renderer, &target, gpu_session.rest());
  CHECK(foreground_fraction(rest_image) > 0.02);

  gpu_session.set_reconstruction(Reconstruction::Gpu, &gpu_renderer);
  cpu_session.set_reconstruction(Reconstruction::Cpu, &cpu_renderer);
  REQUIRE(gpu_session.reconstruction() == Reconstruction::Gpu);
  REQUIRE(cpu_session.reconstruction() == Reconstruction::Cpu);
  std::vector<FrameStats> gpu_stats, cpu_stats;
  scripted_drag(&gpu_session, &gpu_renderer, 6, &gpu_stats);
  scripted_drag(&cpu_session, &cpu_renderer, 6, &cpu_stats);

  // Same solves (no time budget: the same rounds), so the same w, and the
  // two paths must agree up to float rounding of B·w: per coordinate
  // |Δ| ≤ c·p·ε·Σ_j |B_ij w_j| (measured: 1.4 % of this bound).
  Vertices gpu, cpu;
  gpu_renderer.read_positions(&gpu);
  cpu_session.positions(cpu_renderer, &cpu);
  const auto& B = gpu_session.deformer().reconstruction_basis();
  const Eigen::VectorXf& w = gpu_session.deformer().reduced_coordinates();
  REQUIRE(w == cpu_session.deformer().reduced_coordinates());
  REQUIRE(B.rows() == 3 * gpu.rows());
  REQUIRE(B.cols() == w.size());
  const Eigen::VectorXd magnitude = B.cast<double>().cwiseAbs() * w.cast<double>().cwiseAbs();
  const double c = 8.0 * static_cast<double>(B.cols()) * FLT_EPSILON;
  for (Index v = 0; v < gpu.rows(); ++v) {
    const double bound = c * magnitude.segment<3>(3 * v).maxCoeff() + 1e-7;
    INFO("vertex " << v);
    REQUIRE((gpu.row(v) - cpu.row(v)).cwiseAbs().maxCoeff() <= bound);
  }
  // And the handles were met (hard constraints).
  CHECK(gpu_stats.back().handle_residual < 1e-3);
  CHECK(cpu_stats.back().handle_residual < 1e-3);
  // The top moved by about the drag (1.5 sideways).
  const double top_x = gpu.row(ring(kRings - 1)[0]).x() - gpu_session.rest().row(ring(kRings - 1)[0]).x();
  CHECK(top_x > 1.0);

  const Image gpu_image = render(gpu_renderer, &target, gpu_session.rest());
  const Image cpu_image = render(cpu_renderer, &target, cpu_session.rest());
  CHECK(foreground_fraction(gpu_image) > 0.02);
  CHECK(differing_fraction(gpu_image, rest_image) > 0.02);
  // Both paths draw the same surface (normals from the same formula).
  CHECK(differing_fraction(gpu_image, cpu_image, 24) < 0.002);

  // PNG round trip of what was rendered.
  const std::string png = "viewer_test_drag.png";
  write_png(png, gpu_image);
  const Image back = read_png(png);
  CHECK(back.width == kSize);
  CHECK(differing_fraction(back, gpu_image, 0) == 0.0);
  std::remove(png.c_str());

  SECTION("bad input is refused with a message") {
    CHECK_THROWS_AS(gpu_renderer.upload_basis(RowMatrixF::Zero(5, 3), nullptr), std::invalid_argument);
    CHECK_THROWS_AS(gpu_renderer.set_colors({}), std::invalid_argument);
    CHECK_THROWS_AS(gpu_renderer.set_markers(0, {static_cast<unsigned>(gpu_session.rest().rows())}), std::invalid_argument);
    CHECK_THROWS_AS(gpu_session.add_handle({-1}, "bad"), std::invalid_argument);
    CHECK_THROWS_AS(gpu_session.add_handle({}, "empty"), std::invalid_argument);
    CHECK_THROWS_AS(read_png("no-such-file.png"), std::runtime_error);
  }
}

TEST_CASE("headless: the session's handles played through run_scenario give the frames Session::step gives") {
  INFO(gl_context().description());
  Session stepped(cylinder_input()), played(cylinder_input());
  stepped.precompute(stepped.input().options);
  MeshRenderer renderer(stepped.rest(), stepped.input().faces);
  stepped.set_reconstruction(Reconstruction::Cpu, &renderer);
  std::vector<FrameStats> stats;
  scripted_drag(&stepped, &renderer, 4, &stats);

  // The same drag as a scenario: the handles, and frame f's transforms.
  played.add_handle(ring(0), "base");
  played.add_handle(ring(kRings - 1), "top");
  std::vector<Eigen::Matrix4d> top;
  for (int k = 1; k <= 4; ++k) {
    const double t = k / 4.0;
    const Eigen::Affine3d T = Eigen::Translation3d(1.5 * t, 0.0, -0.3 * t) * Eigen::Translation3d(0, 0, 4.0) *
                              Eigen::AngleAxisd(0.8 * t, Eigen::Vector3d::UnitZ()) * Eigen::Translation3d(0, 0, -4.0);
    top.push_back(T.matrix());
  }
  const Scenario sc = played.played_scenario(played.input().options, top.size(),
                                             [&](size_t f) { played.handles()[1].transform = top[f]; });
  REQUIRE(sc.frames.size() == 4);
  CHECK(sc.handles.points.size() == stepped.handle_set().points.size());
  ScenarioRunOptions o;
  o.deformer = played.input().options;
  ScenarioPoses poses;
  const ScenarioRunSummary run = run_scenario(sc, o, played.run_deformer(), &poses);
  REQUIRE(run.ok());
  played.adopt_run(run.precompute, run.options, poses.last);
  CHECK(played.summary().reduced_size == stepped.summary().reduced_size);
  CHECK((played.last_pose() - stepped.last_pose()).cwiseAbs().maxCoeff() <= 1e-12 * stepped.diagonal());
  CHECK(run.handle_residual.back() == Approx(stats.back().handle_residual).margin(1e-12));
  CHECK_THROWS_WITH(Session(cylinder_input()).played_scenario(o.deformer, 1, [](size_t) {}),
                    Catch::Contains("no handle to play"));
}

TEST_CASE("refine worker: the reduced pose refined off the UI thread, shown once, cancelled mid-round") {
  INFO(gl_context().description());
  Session s(cylinder_input());
  s.precompute(s.input().options);
  MeshRenderer renderer(s.rest(), s.input().faces);
  s.set_reconstruction(Reconstruction::Cpu, &renderer);
  std::vector<FrameStats> stats;
  scripted_drag(&s, &renderer, 6, &stats);
  // The per-frame quality readout: rounds run and the fixed-point residual.
  CHECK(stats.back().iterations >= 1);
  CHECK(stats.back().iterations <= s.input().options.iterations);
  CHECK(std::isfinite(stats.back().fixed_point_residual));
  CHECK(stats.back().fixed_point_residual >= 0.0);
  const Vertices reduced = s.last_pose();
  REQUIRE(reduced.rows() == s.rest().rows());

  SECTION("a refine finishes on the worker; its pose is handed over once and drawn") {
    RefineWorker& worker = s.refine_worker();
    CHECK(worker.status().state == RefineStatus::State::Idle);
    worker.start(s.handle_set(), s.targets(), reduced);
    worker.wait_idle();
    const RefineStatus st = worker.status();
    INFO(st.message);
    REQUIRE(st.state == RefineStatus::State::Done);
    CHECK(st.summary.rounds > 0);
    CHECK_FALSE(st.summary.cancelled);
    // Full-space local-global does not raise the classic ARAP energy of the
    // reduced pose, and keeps the (hard) handles.
    CHECK(st.summary.arap_energy <= s.arap_energy(reduced) * (1 + 1e-9));
    CHECK(st.summary.handle_residual / s.diagonal() < 1e-6);
    Vertices refined;
    REQUIRE(worker.poll(&refined));
    CHECK_FALSE(worker.poll(&refined));  // once per job
    REQUIRE(refined.rows() == reduced.rows());
    CHECK(refined.allFinite());
    CHECK(s.arap_energy(refined) == Approx(st.summary.arap_energy).epsilon(1e-9));
    // The readout's distances are those between the reduced and refined poses.
    const Eigen::VectorXd d = (refined - reduced).rowwise().norm();
    CHECK(st.summary.max_from_input == Approx(d.maxCoeff() / s.diagonal()).epsilon(1e-9));
    CHECK(st.summary.rms_from_input > 0.0);
    CHECK(st.summary.rms_from_input <= st.summary.max_from_input);
    // Drawn instead of the last frame: the vertex buffer holds the refined
    // pose (floats), and positions() returns it.
    s.show_pose(refined, &renderer);
    Vertices drawn, shown;
    renderer.read_positions(&drawn);
    s.positions(renderer, &shown);
    CHECK((drawn - refined).cwiseAbs().maxCoeff() <= 1e-6 * s.diagonal());
    CHECK((shown - refined).cwiseAbs().maxCoeff() <= 1e-6 * s.diagonal());
  }

  SECTION("cancel() returns while the worker is inside a round; the pose stays valid; the worker is reusable") {
    RoundLatch latch(2);
    RefineOptions options;
    options.tolerance = 0.0;  // to the converged shape: far more than 2 rounds
    options.distance_tolerance = 0.0;
    RefineWorker worker(s.input().scenario.model, options, latch.hook());
    worker.start(s.handle_set(), s.targets(), reduced);
    REQUIRE(latch.wait_held(worker));
    CHECK(worker.status().state == RefineStatus::State::Running);
    CHECK(worker.status().rounds == 2);
    worker.cancel();
    CHECK(worker.status().state == RefineStatus::State::Cancelled);
    CHECK(latch.inside());  // cancel() did not wait for the round to end
    latch.release();
    Vertices pose;
    CHECK_FALSE(worker.poll(&pose));
    worker.wait_idle();
    CHECK(worker.status().state == RefineStatus::State::Cancelled);
    CHECK_FALSE(worker.poll(&pose));  // a cancelled refine is never swapped in
    const RefineSummary cancelled = worker.last_summary();
    CHECK(cancelled.cancelled);
    CHECK(cancelled.rounds == 2);
    const Vertices last = worker.last_pose();
    REQUIRE(last.rows() == reduced.rows());
    CHECK(last.allFinite());
    CHECK(s.arap_energy(last) <= s.arap_energy(reduced) * (1 + 1e-9));

    worker.start(s.handle_set(), s.targets(), reduced);
    worker.wait_idle();
    REQUIRE(worker.status().state == RefineStatus::State::Done);
    CHECK(worker.status().summary.converged);
    CHECK(worker.poll(&pose));
    CHECK(s.arap_energy(pose) <= s.arap_energy(last) * (1 + 1e-9));
  }

  SECTION("start() while a refine runs replaces it without waiting; only the new job's pose is handed over") {
    RoundLatch latch(1);
    RefineWorker worker(s.input().scenario.model, RefineOptions{}, latch.hook());
    worker.start(s.handle_set(), s.targets(), reduced);
    REQUIRE(latch.wait_held(worker));
    HandleTargets moved = s.targets();  // every handle 0.05 further along each axis
    moved.points.array() += 0.05;
    worker.start(s.handle_set(), moved, reduced);
    CHECK(worker.status().state == RefineStatus::State::Running);  // the new job, queued
    CHECK(latch.inside());                                         // start() did not wait for the first job
    latch.release();
    worker.wait_idle();
    REQUIRE(worker.status().state == RefineStatus::State::Done);
    Vertices pose;
    REQUIRE(worker.poll(&pose));
    const DeformableMesh& model = s.input().scenario.model;
    CHECK(handle_residual(model, s.handle_set(), moved, pose) < 1e-6 * s.diagonal());
    CHECK(handle_residual(model, s.handle_set(), s.targets(), pose) > 0.05);
  }
}

TEST_CASE("RestTimer: a refine starts once per rest, the first frame still_seconds after the last move") {
  RestTimer rest(0.3);
  CHECK_FALSE(rest.update(false, 0.0));  // the first frame counts as a move
  CHECK_FALSE(rest.update(false, 0.2));
  CHECK(rest.update(false, 0.31));
  CHECK_FALSE(rest.update(false, 0.5));  // once per rest
  CHECK_FALSE(rest.update(true, 0.6));   // a handle moves or is held
  CHECK_FALSE(rest.update(false, 0.8));
  CHECK(rest.update(false, 0.95));
  rest.restart();  // e.g. refining switched back on
  CHECK_FALSE(rest.update(false, 1.0));
  CHECK(rest.update(false, 1.35));
}

TEST_CASE("recorded handle motion round trips and bad files are refused") {
  Session s(cylinder_input());
  s.add_handle(ring(0), "base");
  s.add_handle({5}, "tip");
  HandleMotion m;
  for (int f = 0; f < 3; ++f) {
    s.handles()[1].transform(0, 3) = 0.5 * f;
    record_frame(s.handles(), s.rest().rows(), &m);
  }
  const std::string path = "viewer_test_motion.json";
  write_motion(path, m);
  const HandleMotion back = read_motion(path);
  REQUIRE(back.frames.size() == 3);
  REQUIRE(back.handles.size() == 2);
  CHECK(back.handles[0].vertices == ring(0));
  CHECK(back.frames[2][1](0, 3) == 1.0);
  {
    std::FILE* f = std::fopen(path.c_str(), "w");
    std::fputs(R"({"format": "qpr-handle-motion", "version": 1, "vertex_count": 10,
                  "handles": [{"vertices": [12]}], "frames": []})", f);
    std::fclose(f);
  }
  CHECK_THROWS_WITH(read_motion(path), Catch::Contains("/handles/0/vertices"));
  std::remove(path.c_str());
  CHECK_THROWS_AS(read_motion("no-such-motion.json"), std::runtime_error);
}

// The writers behind the window's buttons ("Save screenshot" and a
// recording's "Stop and save"; the window shows their message): on a full
// device, in a missing directory and over a file-size limit each throws
// naming the file, keeps the earlier file byte for byte and leaves no
// temporary. No GL needed. The command-line writers of `qpr view` are cases
// of tests/apps/bad_input.py --group view.
TEST_CASE("the window's writers fail naming the file and keep the earlier one", "[writers]") {
  namespace fs = std::filesystem;
  HandleMotion motion;
  motion.vertex_count = 10;
  motion.handles = {{"h0", {1, 2}, -1}};
  motion.frames.assign(40, {Eigen::Matrix4d::Identity()});
  Image image;
  image.width = image.height = 16;
  image.rgb.assign(3 * 16 * 16, 0);
  for (size_t i = 0; i < image.rgb.size(); ++i) image.rgb[i] = static_cast<std::uint8_t>(i * 37 % 251);
  const std::pair<const char*, std::function<void(const std::string&)>> writers[] = {
      {"recording", [&](const std::string& path) { write_motion(path, motion); }},
      {"screenshot", [&](const std::string& path) { write_png(path, image); }}};
  const std::string earlier = "earlier contents\n" + std::string(4096, 'x');
  for (const auto& [what, write] : writers) {
    INFO(what);
    const fs::path dir = fs::temp_directory_path() / ("qpreduce_viewer_writers_" + std::to_string(::getpid()));
    fs::remove_all(dir);
    fs::create_directories(dir);
    const std::string out = (dir / "out").string();
    std::ofstream(out, std::ios::binary) << earlier;
    write(out + ".ok");  // the writer works at all
    CHECK(fs::file_size(out + ".ok") > 16);
    if (fs::exists("/dev/full")) {
      fs::create_symlink("/dev/full", dir / "full");
      CHECK_THROWS_WITH(write((dir / "full").string()),
                        Catch::Contains("full") && Catch::Contains("No space left on device"));
    }
    CHECK_THROWS_WITH(write((dir / "missing" / "out").string()),
                      Catch::Contains("missing/out") && Catch::Contains("does not exist"));
    {
      const qpreduce_test::FileSizeLimit limit(16);
      CHECK_THROWS_WITH(write(out), Catch::Contains(out) && Catch::Contains("File too large"));
    }
    std::ostringstream now;
    now << std::ifstream(out, std::ios::binary).rdbuf();
    CHECK(now.str() == earlier);
    for (const auto& e : fs::directory_iterator(dir)) {
      const std::string name = e.path().filename().string();
      CHECK((name == "out" || name == "out.ok" || name == "full"));  // no temporary
    }
    fs::remove_all(dir);
  }
}

TEST_CASE("boundary faces of a tet box are its surface") {
  const TetMesh box = shapes::box_tets(1, 1, 1, 2, 2, 2);
  const Triangles F = boundary_faces(box.T);
  CHECK(F.rows() == box.F.rows());  // 6 sides × 2·2 squares × 2 triangles
  // Outward: positive signed volume.
  double volume = 0.0;
  for (Index f = 0; f < F.rows(); ++f)
    volume += box.V.row(F(f, 0)).dot(box.V.row(F(f, 1)).cross(box.V.row(F(f, 2)))) / 6.0;
  CHECK(volume == Approx(1.0));
}

TEST_CASE("lasso: inside_polygon by the even-odd rule, concave outlines included") {
  // An L-shaped outline: (0,0) (4,0) (4,1) (1,1) (1,4) (0,4).
  const std::vector<float> x{0, 4, 4, 1, 1, 0}, y{0, 0, 1, 1, 4, 4};
  CHECK(qpr::viewer::inside_polygon(0.5f, 0.5f, x, y));
  CHECK(qpr::viewer::inside_polygon(3.5f, 0.5f, x, y));
  CHECK(qpr::viewer::inside_polygon(0.5f, 3.5f, x, y));
  CHECK_FALSE(qpr::viewer::inside_polygon(2.0f, 2.0f, x, y));  // the notch
  CHECK_FALSE(qpr::viewer::inside_polygon(5.0f, 0.5f, x, y));
  CHECK_FALSE(qpr::viewer::inside_polygon(0.5f, 0.5f, {0, 1}, {0, 1}));  // not a polygon
}
