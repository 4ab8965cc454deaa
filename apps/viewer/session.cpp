#include "session.h"

#include <qpreduce/deform/deformer/selection_handles.h>
#include <qpreduce/deform/energy/arap_energy.h>
#include <qpreduce/deform/mesh/geometry.h>
#include <qpreduce/deform/proxies/proxies.h>
#include <qpreduce/checks.h>
#include <qpreduce/util/timer.h>

#include <fmt/format.h>

#include <algorithm>
#include <stdexcept>

namespace qpr::viewer {

using namespace qpreduce;
using namespace qpreduce::deform;

const char* to_string(Reconstruction r) { return r == Reconstruction::Gpu ? "GPU (vertex shader, transform feedback)" : "CPU"; }

namespace {

Eigen::Matrix4d translation(const Eigen::Vector3d& t) {
  Eigen::Matrix4d T = Eigen::Matrix4d::Identity();
  T.block<3, 1>(0, 3) = t;
  return T;
}

Eigen::Vector3d point_rest(const PointHandle& h, const Vertices& V) {
  if (h.weights.empty()) return V.row(h.vertices[0]).transpose();
  Eigen::Vector3d p = Eigen::Vector3d::Zero();
  for (size_t i = 0; i < h.vertices.size(); ++i) p += h.weights[i] * V.row(h.vertices[i]).transpose();
  return p;
}

}  // namespace

Session::Session(ViewerInput input) : input_(std::move(input)), deformer_(std::make_unique<Deformer>()) {
  diagonal_ = bounding_box_diagonal(input_.scenario.model.V);
  constraints_ = input_.scenario.constraints;
}

Session::~Session() {
  if (worker_.joinable()) worker_.join();
}

// ---- precompute ----

namespace {
// Linear proxies are sampled here (as precompute would) so that the viewer can
// colour them; precompute then uses exactly these. `exact`: the point-handle
// vertices of these handles first (ViewerInput::exact_handles).
void ensure_linear_proxies(DeformableMesh* model, Index count, const Handles* exact) {
  if (exact && !exact->points.empty()) {
    model->linear = exact_handle_proxies(*model, *exact, count);
    return;
  }
  if (model->linear.count() == count && count > 0) return;
  const bool tet = model->is_tet();
  model->linear = tet ? linear_proxies_fps(model->V, model->T, count) : linear_proxies_fps(model->V, model->F, count);
}
}  // namespace

void Session::sample_linear_proxies(const DeformerOptions& options) {
  if (!input_.scenario.model.linear.count() || options.linear_proxies != options_.linear_proxies)
    ensure_linear_proxies(&input_.scenario.model, options.linear_proxies, exact_handles());
}

void Session::precompute(const DeformerOptions& options, const ProgressFn& progress) {
  if (worker_.joinable()) throw std::logic_error("Session::precompute: a precompute is running");
  std::string why;
  if (!options.is_valid(&why)) throw std::invalid_argument("deformer options: " + why);
  sample_linear_proxies(options);
  auto d = std::make_unique<Deformer>();
  const PrecomputeSummary s = d->precompute(input_.scenario.model, options, progress);
  if (!s.ok()) throw std::runtime_error("precompute failed: " + s.message);
  deformer_ = std::move(d);
  summary_ = s;
  options_ = options;
  basis_uploaded_ = false;
  constraints_ready_ = false;
}

void Session::precompute_async(const DeformerOptions& options) {
  if (worker_.joinable()) return;
  error_.clear();
  std::string why;
  if (!options.is_valid(&why)) {
    error_ = "deformer options: " + why;
    return;
  }
  progress_ = 0.0;
  done_ = false;
  pending_options_ = options;
  // Proxy sampling is cheap next to the subspace build; done here so that the
  // worker only reads the model.
  DeformableMesh model = input_.scenario.model;
  if (model.linear.count() != options.linear_proxies) {
    try {
      ensure_linear_proxies(&model, options.linear_proxies, exact_handles());
    } catch (const std::exception& e) {
      error_ = e.what();
      return;
    }
  }
  worker_ = std::thread([this, model = std::move(model), options]() mutable {
    try {
      auto d = std::make_unique<Deformer>();
      pending_summary_ = d->precompute(model, options, [this](const std::string& stage, double fraction) {
        progress_ = fraction;
        std::lock_guard<std::mutex> lock(stage_mutex_);
        stage_ = stage;
      });
      if (pending_summary_.ok()) {
        pending_ = std::move(d);
        input_linear_pending_ = std::move(model.linear);
      } else {
        std::lock_guard<std::mutex> lock(stage_mutex_);
        error_ = "precompute failed: " + pending_summary_.message;
      }
    } catch (const std::exception& e) {
      std::lock_guard<std::mutex> lock(stage_mutex_);
      error_ = e.what();
    }
    done_ = true;
  });
}

bool Session::poll() {
  if (!worker_.joinable() || !done_) return false;
  worker_.join();
  if (!pending_) return false;
  deformer_ = std::move(pending_);
  summary_ = pending_summary_;
  options_ = pending_options_;
  input_.scenario.model.linear = std::move(input_linear_pending_);
  basis_uploaded_ = false;
  constraints_ready_ = false;
  return true;
}

std::string Session::progress_stage() const {
  std::lock_guard<std::mutex> lock(stage_mutex_);
  return stage_;
}

// ---- handles ----

void Session::handles_from_scenario() {
  handles_.clear();
  const Scenario& sc = input_.scenario;
  for (size_t i = 0; i < sc.handles.points.size(); ++i) {
    ViewHandle h;
    h.name = fmt::format("point {}", i);
    h.points = {sc.handles.points[i]};
    h.rest = point_rest(sc.handles.points[i], sc.model.V).transpose();
    h.pivot = h.rest.row(0).transpose();
    for (Index v : sc.handles.points[i].vertices) h.vertices.push_back(static_cast<unsigned>(v));
    h.scenario_point = static_cast<int>(i);
    handles_.push_back(std::move(h));
  }
  for (size_t j = 0; j < sc.handles.patches.size(); ++j) {
    ViewHandle h;
    h.patch = static_cast<int>(sc.handles.patches[j]);
    h.name = fmt::format("patch {}", h.patch);
    Eigen::Vector3d c = Eigen::Vector3d::Zero();
    for (size_t v = 0; v < sc.model.patch_of_vertex.size(); ++v)
      if (sc.model.patch_of_vertex[v] == h.patch) {
        h.vertices.push_back(static_cast<unsigned>(v));
        c += sc.model.V.row(static_cast<Index>(v)).transpose();
      }
    h.pivot = c / std::max<double>(1.0, static_cast<double>(h.vertices.size()));
    h.scenario_patch = static_cast<int>(j);
    handles_.push_back(std::move(h));
  }
  pose_scenario_frame(0);
  constraints_ready_ = false;
}

void Session::pose_scenario_frame(size_t f) {
  const Scenario& sc = input_.scenario;
  if (sc.frames.empty()) return;
  const HandleTargets& t = sc.frames[std::min(f, sc.frames.size() - 1)];
  for (ViewHandle& h : handles_) {
    if (h.scenario_point >= 0) {
      h.transform = translation(t.points.row(h.scenario_point).transpose() - h.rest.row(0).transpose());
    } else if (h.scenario_patch >= 0) {
      h.transform.setIdentity();
      h.transform.topRows<3>() = t.patch_transforms[h.scenario_patch];
    }
  }
}

void Session::add_handle(const std::vector<int>& vertices, const std::string& name) {
  const Vertices& V = input_.scenario.model.V;
  if (vertices.empty()) throw std::invalid_argument("add_handle: no vertex selected");
  for (int v : vertices)
    if (v < 0 || v >= V.rows()) throw std::invalid_argument(fmt::format("add_handle: vertex {} outside [0, {})", v, V.rows()));
  ViewHandle h;
  h.name = name;
  SelectionHandles grab = selection_handles(V, vertices);
  h.pivot = grab.centroid;
  h.points = std::move(grab.points);
  h.rest.resize(static_cast<Index>(h.points.size()), 3);
  for (size_t j = 0; j < h.points.size(); ++j) h.rest.row(static_cast<Index>(j)) = point_rest(h.points[j], V).transpose();
  for (int v : vertices) h.vertices.push_back(static_cast<unsigned>(v));
  handles_.push_back(std::move(h));
  constraints_ready_ = false;
}

void Session::remove_handle(size_t index) {
  if (index >= handles_.size()) return;
  handles_.erase(handles_.begin() + static_cast<std::ptrdiff_t>(index));
  constraints_ready_ = false;
}

void Session::form_handle_set() {
  flat_ = Handles{};
  for (const ViewHandle& h : handles_) {
    if (h.patch >= 0) flat_.patches.push_back(h.patch);
    else flat_.points.insert(flat_.points.end(), h.points.begin(), h.points.end());
  }
  targets_.points.resize(static_cast<Index>(flat_.points.size()), 3);
  targets_.patch_transforms.resize(flat_.patches.size());
  residual_scenario_.model = input_.scenario.model;
  residual_scenario_.handles = flat_;
}

double Session::update_constraints(std::string* note) {
  form_handle_set();
  const Timer t;
  const ConstraintSummary cs = deformer_->set_handles(flat_, constraints_);
  const double ms = 1e3 * t.seconds();
  if (!usable(cs.status)) throw std::runtime_error("handles: " + cs.message);
  if (note) *note = cs.status == Status::Success ? std::string() : cs.message;
  constraints_ready_ = true;
  return ms;
}

// ---- a whole run ----

Scenario Session::played_scenario(const DeformerOptions& options, size_t frames,
                                  const std::function<void(size_t)>& pose) {
  if (handles_.empty()) throw std::invalid_argument("Session::played_scenario: no handle to play");
  std::string why;
  if (!options.is_valid(&why)) throw std::invalid_argument("deformer options: " + why);
  sample_linear_proxies(options);
  form_handle_set();
  Scenario played;
  played.model = input_.scenario.model;
  played.handles = flat_;
  played.constraints = constraints_;
  for (size_t f = 0; f < frames; ++f) {
    pose(f);
    fill_targets();
    played.frames.push_back(targets_);
  }
  return played;
}

void Session::adopt_run(const PrecomputeSummary& precompute, const DeformerOptions& options, const Vertices& last) {
  check_size("Session::adopt_run: rows", rest().rows(), last.rows());
  summary_ = precompute;
  options_ = options;
  form_handle_set();
  constraints_ready_ = true;
  cpu_out_ = last;
}

void Session::fill_targets() {
  Index row = 0;
  size_t patch = 0;
  for (const ViewHandle& h : handles_) {
    if (h.patch >= 0) {
      targets_.patch_transforms[patch++] = h.transform.topRows<3>();
      continue;
    }
    for (Index j = 0; j < h.rest.rows(); ++j)
      targets_.points.row(row++) = (h.transform.topLeftCorner<3, 3>() * h.rest.row(j).transpose() +
                                    h.transform.topRightCorner<3, 1>()).transpose();
  }
}

// ---- frames ----

void Session::set_reconstruction(Reconstruction wanted, MeshRenderer* renderer) {
  wanted_ = wanted;
  if (wanted == Reconstruction::Cpu) {
    path_ = Reconstruction::Cpu;
    return;
  }
  if (!basis_uploaded_) {
    gpu_reason_.clear();
    basis_uploaded_ = true;
    // The GPU reconstructs in float whatever the deformer keeps
    // (DeformerOptions::double_basis: a float copy for the upload).
    const bool uploaded = deformer_->double_basis()
                                  ? renderer->upload_basis(deformer_->reconstruction_basis_double().cast<float>(),
                                                           &gpu_reason_)
                                  : renderer->upload_basis(deformer_->reconstruction_basis(), &gpu_reason_);
    if (!uploaded) {
      path_ = Reconstruction::Cpu;
      return;
    }
  }
  path_ = renderer->has_basis() ? Reconstruction::Gpu : Reconstruction::Cpu;
}

FrameStats Session::step(MeshRenderer* renderer) {
  if (!deformer_->ready()) throw std::logic_error("Session::step: precompute first");
  if (!basis_uploaded_ && wanted_ == Reconstruction::Gpu) set_reconstruction(wanted_, renderer);
  if (!constraints_ready_) update_constraints(nullptr);
  fill_targets();
  FrameStats stats;
  const auto rounds = [&stats](const FrameSummary& fs) {
    stats.fixed_point_residual = fs.fixed_point_residual;
    stats.iterations = fs.iterations;
    stats.stop = fs.stop;
    stats.solve_ms = 1e3 * fs.solve_seconds;
    stats.iteration_us = 1e6 * fs.solve_seconds / std::max(1, fs.iterations);
  };
  const Timer total;
  if (path_ == Reconstruction::Gpu) {
    rounds(deformer_->frame(targets_, nullptr));
    const Timer t;
    const auto& frame = deformer_->normalization();
    renderer->reconstruct_gpu(deformer_->reduced_coordinates(),
                              (frame.scale * deformer_->global_rotation()).cast<float>(), frame.centre.cast<float>());
    glFinish();  // honest timing: wait for the GPU
    stats.reconstruction_ms = 1e3 * t.seconds();
  } else {
    const FrameSummary fs = deformer_->frame(targets_, &cpu_out_);
    rounds(fs);
    const Timer t;
    renderer->upload_positions(cpu_out_);
    glFinish();
    stats.reconstruction_ms = 1e3 * (fs.reconstruct_seconds + t.seconds());
  }
  stats.frame_ms = 1e3 * total.seconds();
  // The residual needs the positions: read back on the GPU path (not timed).
  if (path_ == Reconstruction::Gpu) renderer->read_positions(&cpu_out_);
  stats.handle_residual = handle_residual(residual_scenario_, targets_, cpu_out_) / diagonal_;
  return stats;
}

void Session::positions(const MeshRenderer& renderer, Vertices* V) const {
  if (path_ == Reconstruction::Gpu) renderer.read_positions(V);
  else *V = cpu_out_;
}

void Session::show_pose(const Vertices& V, MeshRenderer* renderer) {
  check_size("Session::show_pose: rows", rest().rows(), V.rows());
  renderer->upload_positions(V);
  if (path_ == Reconstruction::Cpu) cpu_out_ = V;  // what positions() returns on this path
}

double Session::arap_energy(const Vertices& V) const {
  check_size("Session::arap_energy: rows", rest().rows(), V.rows());
  return qpreduce::deform::arap_energy(rest(), deformer_->elements(), V);
}

RefineWorker& Session::refine_worker(const RefineOptions& options) {
  if (!refine_) refine_ = std::make_unique<RefineWorker>(input_.scenario.model, options);
  return *refine_;
}

}  // namespace qpr::viewer
