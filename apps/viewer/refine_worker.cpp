#include "refine_worker.h"

#include <algorithm>
#include <chrono>
#include <exception>
#include <stdexcept>

namespace qpr::viewer {

using namespace qpreduce::deform;

namespace {
double now_seconds() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}
}  // namespace

const char* to_string(RefineStatus::State s) {
  switch (s) {
    case RefineStatus::State::Idle: return "idle";
    case RefineStatus::State::Running: return "running";
    case RefineStatus::State::Done: return "done";
    case RefineStatus::State::Cancelled: return "cancelled";
    case RefineStatus::State::Failed: return "failed";
  }
  return "?";
}

bool RestTimer::update(bool moved, double now) {
  if (moved || !seen_) {
    since_ = now;
    seen_ = true;
    fired_ = false;
    return false;
  }
  if (fired_ || now - since_ < still_seconds_) return false;
  fired_ = true;
  return true;
}

RefineWorker::RefineWorker(DeformableMesh model, const RefineOptions& options, RoundHook hook)
    : model_(std::move(model)), options_(options), hook_(std::move(hook)) {
  // The worker runs beside the render loop: by default it leaves that loop
  // a core (RefineOptions::threads 0 would take them all).
  if (options_.threads == 0) options_.threads = std::max(1, static_cast<int>(std::thread::hardware_concurrency()) - 1);
  std::string why;
  if (!options_.is_valid(&why)) throw std::invalid_argument("refine options: " + why);
  thread_ = std::thread([this] { loop(); });
}

RefineWorker::~RefineWorker() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stop_ = true;
    queued_.reset();
  }
  ++generation_;  // the running refine stops before its next round
  wake_.notify_all();
  thread_.join();
}

void RefineWorker::start(const Handles& handles, const HandleTargets& targets, const Vertices& pose) {
  std::lock_guard<std::mutex> lock(mutex_);
  queued_ = Job{handles, targets, pose, ++generation_};
  cancelled_ = false;
  wake_.notify_one();
}

void RefineWorker::cancel() {
  std::lock_guard<std::mutex> lock(mutex_);
  queued_.reset();
  if (generation_ > 0 && !cancelled_) {
    cancelled_ = true;
    ++generation_;
  }
}

bool RefineWorker::poll(Vertices* pose) {
  std::lock_guard<std::mutex> lock(mutex_);
  const std::uint64_t current = generation_;
  if (finished_generation_ != current || !finished_ok_ || taken_generation_ == current) return false;
  taken_generation_ = current;
  *pose = pose_;
  return true;
}

RefineStatus RefineWorker::status() const {
  std::lock_guard<std::mutex> lock(mutex_);
  RefineStatus s;
  s.summary = summary_;
  const std::uint64_t current = generation_;
  if (current == 0) return s;
  if (cancelled_) {
    s.state = RefineStatus::State::Cancelled;
  } else if (finished_generation_ == current) {
    s.state = finished_ok_ ? RefineStatus::State::Done : RefineStatus::State::Failed;
    s.rounds = summary_.rounds;
    s.seconds = summary_.seconds;
    s.message = error_;
  } else {
    s.state = RefineStatus::State::Running;
    const bool mine = busy_ && running_generation_ == current;
    s.preparing = !mine || preparing_;
    s.rounds = mine ? rounds_.load() : 0;
    s.seconds = mine ? now_seconds() - started_at_ : 0.0;
  }
  return s;
}

void RefineWorker::wait_idle() {
  std::unique_lock<std::mutex> lock(mutex_);
  idle_.wait(lock, [this] { return !busy_ && !queued_; });
}

RefineSummary RefineWorker::last_summary() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return summary_;
}

Vertices RefineWorker::last_pose() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return pose_;
}

void RefineWorker::loop() {
  std::unique_lock<std::mutex> lock(mutex_);
  for (;;) {
    wake_.wait(lock, [this] { return stop_ || queued_.has_value(); });
    if (stop_) return;
    Job job = std::move(*queued_);
    queued_.reset();
    busy_ = true;
    running_generation_ = job.generation;
    started_at_ = now_seconds();
    rounds_ = 0;
    preparing_ = true;
    lock.unlock();
    run(std::move(job));
    lock.lock();
    busy_ = false;
    idle_.notify_all();
  }
}

// On the worker thread, without the mutex except to publish the result.
void RefineWorker::run(Job job) {
  RefineSummary summary;
  Vertices out;
  std::string error;
  try {
    if (!refiner_) {  // built once, here, so that the UI never waits for it
      Refiner r;
      r.precompute(model_, options_);
      refiner_ = std::move(r);
    }
    const auto cancel = [this, &job](int rounds) {
      rounds_ = rounds;
      preparing_ = false;
      if (hook_) hook_(rounds);
      return generation_.load() != job.generation;
    };
    int calls = 0;  // the Refiner asks once before each round
    summary = refiner_->refine(job.handles, job.targets, job.pose, &out, [&] { return cancel(calls++); });
    if (!summary.usable()) error = summary.message;
  } catch (const std::exception& e) {
    error = e.what();
  }
  if (out.rows() != job.pose.rows()) out = job.pose;  // nothing ran: keep the input pose
  // The per-round traces are not shown; dropped so that status() copies
  // nothing large every frame.
  summary.round_energy = {};
  summary.round_seconds = {};
  std::lock_guard<std::mutex> lock(mutex_);
  finished_ok_ = error.empty() && !summary.cancelled;
  summary_ = std::move(summary);
  pose_ = std::move(out);
  error_ = std::move(error);
  finished_generation_ = job.generation;
}

}  // namespace qpr::viewer
