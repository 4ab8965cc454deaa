// qpr viewer — the full-space finish ("refine") of the reduced pose on a
// worker thread, so that the window keeps drawing reduced frames meanwhile.
//
// One long-lived thread owns a qpreduce::deform::Refiner (refine.h), built
// for the session's model the first time a refine is asked for (on the
// thread: the UI never waits for it). start() hands the thread a job (handles,
// targets, the reduced pose); cancel() only bumps a generation counter that
// the Refiner's per-round cancel hook compares, so it returns at once and the
// refine stops before its next round. Nothing on the UI thread joins or waits
// except the destructor and wait_idle() (headless runs and tests).
//
// Usage (UI thread, once per frame):
//   worker.start(handles, targets, reduced_pose);   // the handles rest
//   worker.cancel();                                // a handle moves
//   if (worker.poll(&pose)) show(pose);             // a finished refine
//   RefineStatus s = worker.status();               // for the panel
#pragma once

#include <qpreduce/deform/refine/refine.h>

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <mutex>
#include <optional>
#include <string>
#include <thread>

namespace qpr::viewer {

// What the panel shows of the refine.
struct RefineStatus {
  enum class State {
    Idle,       // nothing asked yet
    Running,    // the current job (preparing: building the Refiner or factoring the handle set)
    Done,       // the current job finished; summary is its RefineSummary
    Cancelled,  // the current job was cancelled (summary: the last finished job, if any)
    Failed,     // the current job threw or its summary is not usable; message says why
  } state = State::Idle;
  bool preparing = false;  // Running, before the first round (precompute / factorization)
  int rounds = 0;          // Running: rounds done so far
  double seconds = 0.0;    // Running: since start(); Done: the summary's seconds
  // Done: its summary (the last finished job's otherwise), without the
  // per-round traces round_energy / round_seconds.
  qpreduce::deform::RefineSummary summary;
  std::string message;
};
const char* to_string(RefineStatus::State s);

// When the handles count as resting: fed once per displayed frame, it says
// "start" the first frame `still_seconds` after the last move, once per rest.
class RestTimer {
 public:
  explicit RestTimer(double still_seconds) : still_seconds_(still_seconds) {}
  // moved: a handle moved or is held, or the handle set changed, this frame;
  // now: seconds on any steady clock. True once per rest.
  bool update(bool moved, double now);
  // The next update() counts as a move (e.g. refining was switched back on).
  void restart() { seen_ = false; }

 private:
  double still_seconds_, since_ = 0.0;
  bool seen_ = false, fired_ = false;
};

class RefineWorker {
 public:
  // Called on the worker thread before each round with the rounds done so far
  // (0 before the first); may be empty. For tests that must act at a known
  // round without timing.
  using RoundHook = std::function<void(int rounds)>;

  // Keeps a copy of `model` (the rest pose the Refiner is built for) and
  // starts the thread; the Refiner itself is built by the first job.
  RefineWorker(qpreduce::deform::DeformableMesh model, const qpreduce::deform::RefineOptions& options = {},
               RoundHook hook = {});
  ~RefineWorker();  // cancels, then joins
  RefineWorker(const RefineWorker&) = delete;
  RefineWorker& operator=(const RefineWorker&) = delete;

  // Replaces any job not yet begun and cancels the running one; the thread
  // takes this one next. `pose` is n × 3 (the reduced pose to start from).
  void start(const qpreduce::deform::Handles& handles, const qpreduce::deform::HandleTargets& targets,
             const qpreduce::deform::Vertices& pose);
  // Cancels the current job (running or queued). Returns at once.
  void cancel();
  // UI thread: true (once per job) when the current job has finished
  // uncancelled and usable; its pose is copied into *pose.
  bool poll(qpreduce::deform::Vertices* pose);
  RefineStatus status() const;
  // Blocks until the thread has no job (headless runs and tests only).
  void wait_idle();
  // The last job the thread finished (cancelled or not): its summary and
  // pose, for tests and the headless report.
  qpreduce::deform::RefineSummary last_summary() const;
  qpreduce::deform::Vertices last_pose() const;

 private:
  struct Job {
    qpreduce::deform::Handles handles;
    qpreduce::deform::HandleTargets targets;
    qpreduce::deform::Vertices pose;
    std::uint64_t generation = 0;
  };

  qpreduce::deform::DeformableMesh model_;
  qpreduce::deform::RefineOptions options_;
  RoundHook hook_;
  std::optional<qpreduce::deform::Refiner> refiner_;  // worker thread only

  // The generation of the job the UI wants; a job whose generation differs is
  // cancelled (checked by the Refiner once per round).
  std::atomic<std::uint64_t> generation_{0};
  std::atomic<int> rounds_{0};
  std::atomic<bool> preparing_{false};

  mutable std::mutex mutex_;  // guards everything below
  std::condition_variable wake_, idle_;
  std::optional<Job> queued_;
  bool busy_ = false, stop_ = false;
  bool cancelled_ = false;  // cancel() since the last start()
  std::uint64_t running_generation_ = 0, finished_generation_ = 0, taken_generation_ = 0;
  double started_at_ = 0.0;  // seconds on the steady clock when the running job began
  bool finished_ok_ = false;
  qpreduce::deform::RefineSummary summary_;
  qpreduce::deform::Vertices pose_;
  std::string error_;
  std::thread thread_;  // last: starts after the members it uses exist

  void loop();
  void run(Job job);
};

}  // namespace qpr::viewer
