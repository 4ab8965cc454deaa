// qpr run files — what a run writes, committed together at its end.
//
// The rule every qpr command follows (docs/robustness.md, "What a failing
// run writes"): a run that fails writes nothing. Each output is written
// during the run to a staged file beside its target; when the run has
// succeeded (exit 0) or ended with a verdict its command declares (qpr
// check's findings, a violated bound), the staged files are renamed over
// their targets together; when it fails (an error, a numerical failure,
// an exception), they are removed, and so are the directories the run
// created for its outputs (when empty). Earlier files stay as they were.
// Writes the user asks for while a window is open (the viewer's panel
// buttons) are not a run's outputs: they are written at once.
#pragma once

#include <string>
#include <utility>
#include <vector>

namespace qpr {

class RunFiles {
 public:
  RunFiles() = default;
  RunFiles(const RunFiles&) = delete;
  RunFiles& operator=(const RunFiles&) = delete;
  ~RunFiles() { discard(); }

  // The path to write `target` to during the run: "<dir>/.qpr-run.<pid>.<n>.<name>"
  // (the name last, so that writers that go by the extension still see it),
  // or `target` itself when it exists and is not a regular file (/dev/null,
  // a FIFO: written in place, as AtomicFile does). Files a writer makes
  // beside it with the same stem (TetGen's .ele and .face next to .node)
  // are committed with it.
  std::string stage(const std::string& target);
  // Creates `dir` and its missing parents, remembering those it created.
  // Throws qpreduce::FileError when it cannot.
  void create_directories(const std::string& dir);
  // Renames every staged file over its target, in the order staged. Throws
  // qpreduce::FileError when a rename fails (the rest are then discarded).
  void commit();
  // Removes every staged file, then the directories created, when empty.
  void discard() noexcept;
  // `message` with each staged path replaced by its target (for errors
  // raised while writing a staged file).
  std::string plain(std::string message) const;

 private:
  std::vector<std::pair<std::string, std::string>> staged_;  // (staged, target)
  std::vector<std::string> created_;                          // directories, outermost first
  unsigned counter_ = 0;
};

// The outputs of this process's current run: qpr's run_guarded begins and
// ends them around every subcommand.
RunFiles& run_files();

}  // namespace qpr
