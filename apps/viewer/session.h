// qpr viewer — the deformation session behind the window: the Deformer, the
// handles the user (or a scenario) moves, and one step per displayed frame.
//
// A handle is a set of point handles moved together by one rigid/affine map T
// (4 × 4, column vectors): point j goes to T·rest_j, where rest_j = Σ_i w_i v_i
// is its rest position; or a prescribed affine patch whose transform is T
// itself. A handle made from a selection of k > 4 vertices is represented by at
// most 4 weighted points (the means of the selection's quadrants along its two
// main axes), so it costs ≤ 12 constraint rows however large the selection is,
// and still fixes a rigid motion (3 non-collinear points).
//
// Each step: targets from the handles → Deformer::frame (k rounds of Phase 1
// and Phase 2) → positions and normals in the renderer's buffers, either on the
// GPU (upload only w = [X; S_local] and r₀) or on the CPU (Deformer's own
// reconstruction, then upload).
#pragma once

#include "refine_worker.h"
#include "renderer.h"

#include <qpreduce/deform/deformer/deformer.h>
#include <qpreduce/deform/io/scenario.h>

#include <atomic>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

namespace qpr::viewer {

struct ViewHandle {
  std::string name;
  std::vector<qpreduce::deform::PointHandle> points;
  qpreduce::deform::Vertices rest;          // points.size() × 3
  int patch = -1;                           // a prescribed patch instead of points
  Eigen::Matrix4d transform = Eigen::Matrix4d::Identity();
  Eigen::Vector3d pivot = Eigen::Vector3d::Zero();  // rest centre, for rotations
  std::vector<unsigned> vertices;           // drawn as markers
  int scenario_point = -1;                  // from scenario point handle #i (playback)
  int scenario_patch = -1;                  // from scenario patch handle #j (playback)
};

// The inputs of a session (built by `qpr view` from the command line).
struct ViewerInput {
  qpreduce::deform::Scenario scenario;
  qpreduce::deform::Triangles faces;  // triangles drawn (tets: the boundary)
  qpreduce::deform::DeformerOptions options;
  std::string name;
  // The scenario's point-handle vertices are linear proxies (qpr view
  // --exact-handles: exact_handle_proxies, re-sampled with the proxy count).
  bool exact_handles = false;
};

enum class Reconstruction { Gpu, Cpu };
const char* to_string(Reconstruction r);

// Per-frame timings (milliseconds unless named otherwise).
struct FrameStats {
  double iteration_us = 0.0;      // one Phase 1 + Phase 2 round
  double solve_ms = 0.0;          // all rounds of the frame
  double reconstruction_ms = 0.0; // w → positions and normals in GPU buffers (either path)
  double frame_ms = 0.0;          // solve + reconstruction
  double handle_residual = 0.0;   // max over constrained points / bbox diagonal
  // How far the pose is from the alternation's fixed point after the frame's
  // rounds (FrameSummary::fixed_point_residual, ‖ΔS‖/‖S‖), and those rounds.
  double fixed_point_residual = 0.0;
  int iterations = 0;
  qpreduce::RoundStop stop = qpreduce::RoundStop::RoundLimit;  // what ended the rounds (FrameSummary::stop)
};

class Session {
 public:
  explicit Session(ViewerInput input);
  ~Session();

  const ViewerInput& input() const { return input_; }
  const qpreduce::deform::Vertices& rest() const { return input_.scenario.model.V; }
  double diagonal() const { return diagonal_; }

  // ---- precompute ----
  // Synchronous (headless); `progress` may be empty. Throws on failure.
  void precompute(const qpreduce::deform::DeformerOptions& options, const qpreduce::deform::ProgressFn& progress = {});
  // On a worker thread; the current deformer keeps serving frames until
  // poll() installs the new one (returns true then). Errors end up in
  // precompute_error().
  void precompute_async(const qpreduce::deform::DeformerOptions& options);
  bool poll();
  bool precomputing() const { return worker_.joinable(); }
  double progress() const { return progress_.load(); }
  std::string progress_stage() const;
  const std::string& precompute_error() const { return error_; }
  const qpreduce::deform::PrecomputeSummary& summary() const { return summary_; }
  const qpreduce::deform::Deformer& deformer() const { return *deformer_; }
  const qpreduce::deform::DeformerOptions& options() const { return options_; }
  // Linear proxies used (computed by farthest-point sampling when the model has none).
  const qpreduce::deform::LinearProxies& linear_proxies() const { return input_.scenario.model.linear; }

  // ---- handles ----
  std::vector<ViewHandle>& handles() { return handles_; }
  // Handles of the scenario (its point handles and prescribed patches), posed at frame 0.
  void handles_from_scenario();
  // A handle made of `vertices` (see the file comment). Throws std::invalid_argument on bad indices.
  void add_handle(const std::vector<int>& vertices, const std::string& name);
  void remove_handle(size_t index);
  // Poses the scenario handles as in scenario frame f (clamped).
  void pose_scenario_frame(size_t f);
  size_t scenario_frames() const { return input_.scenario.frames.size(); }
  // Re-forms the constraints (the "OP" step) after handles were added or
  // removed. Returns its time in ms; the status message, when not plain
  // success, in *note.
  double update_constraints(std::string* note);
  qpreduce::ConstraintOptions& constraint_options() { return constraints_; }

  // ---- frames ----
  // Reconstruction actually used: GPU when requested and the basis fitted.
  Reconstruction reconstruction() const { return path_; }
  const std::string& gpu_unavailable_reason() const { return gpu_reason_; }
  // Chooses the path; uploads the basis for the GPU (once per precompute).
  void set_reconstruction(Reconstruction wanted, MeshRenderer* renderer);
  // One frame at the current handle targets into the renderer's buffers.
  FrameStats step(MeshRenderer* renderer);
  // The last frame's positions (read back from the renderer for the GPU path).
  void positions(const MeshRenderer& renderer, qpreduce::deform::Vertices* V) const;
  // The handle set and targets of the last frame, and its pose (n × 3, read
  // back on the GPU path): what a refine starts from.
  const qpreduce::deform::Handles& handle_set() const { return flat_; }
  const qpreduce::deform::HandleTargets& targets() const { return targets_; }
  const qpreduce::deform::Vertices& last_pose() const { return cpu_out_; }
  // Draws `V` (n × 3, e.g. a refined pose) instead of the last frame until
  // the next step; positions() then returns it.
  void show_pose(const qpreduce::deform::Vertices& V, MeshRenderer* renderer);
  // Classic ARAP energy (arap_energy.h) of a pose V (n × 3) against the rest
  // pose, over the deformer's rotation elements.
  double arap_energy(const qpreduce::deform::Vertices& V) const;

  // ---- a whole run (the headless mode: qpreduce::deform::run_scenario) ----
  // The scenario the session's handles play over `frames` frames, frame f
  // posed by pose(f) (pose_scenario_frame, or a recorded motion): the model
  // with the linear proxies `options` asks for (sampled as precompute
  // samples them), the handle set update_constraints forms and one
  // HandleTargets a frame. Throws std::invalid_argument with no handle.
  qpreduce::deform::Scenario played_scenario(const qpreduce::deform::DeformerOptions& options, size_t frames,
                                             const std::function<void(size_t)>& pose);
  // The session's deformer, for run_scenario to prepare and run (call
  // set_reconstruction from its `prepared` hook for the GPU path).
  qpreduce::deform::Deformer* run_deformer() { return deformer_.get(); }
  // After run_scenario ran played_scenario(…) on run_deformer(): its model,
  // options and handle set are the session's, `last` (n × 3) its last pose.
  void adopt_run(const qpreduce::deform::PrecomputeSummary& precompute,
                 const qpreduce::deform::DeformerOptions& options, const qpreduce::deform::Vertices& last);

  // ---- full-space refine (refine_worker.h) ----
  // The session's worker, made on first use with `options` (later calls
  // return the same worker and ignore them).
  RefineWorker& refine_worker(const qpreduce::deform::RefineOptions& options = {});

 private:
  // The handles whose vertices are linear proxies (ViewerInput::exact_handles), or null.
  const qpreduce::deform::Handles* exact_handles() const {
    return input_.exact_handles ? &input_.scenario.handles : nullptr;
  }
  ViewerInput input_;
  double diagonal_ = 1.0;
  std::unique_ptr<qpreduce::deform::Deformer> deformer_, pending_;
  qpreduce::deform::PrecomputeSummary summary_, pending_summary_;
  qpreduce::deform::DeformerOptions options_, pending_options_;
  std::thread worker_;
  std::atomic<double> progress_{0.0};
  std::atomic<bool> done_{false};
  mutable std::mutex stage_mutex_;
  std::string stage_, error_;
  std::vector<ViewHandle> handles_;
  qpreduce::deform::Handles flat_;
  qpreduce::deform::HandleTargets targets_;
  qpreduce::ConstraintOptions constraints_;
  bool constraints_ready_ = false;
  Reconstruction wanted_ = Reconstruction::Gpu, path_ = Reconstruction::Cpu;
  bool basis_uploaded_ = false;
  std::string gpu_reason_;
  qpreduce::deform::Vertices cpu_out_;
  qpreduce::deform::Scenario residual_scenario_;  // flat_ as a scenario, for handle_residual
  qpreduce::deform::LinearProxies input_linear_pending_;  // the proxies of the pending deformer
  std::unique_ptr<RefineWorker> refine_;                  // last: destroyed (joined) first

  void fill_targets();
  // The model's linear proxies for `options` (precompute then uses exactly these).
  void sample_linear_proxies(const qpreduce::deform::DeformerOptions& options);
  // flat_, the targets' sizes and residual_scenario_ from the handles.
  void form_handle_set();
};

}  // namespace qpr::viewer
