// qpreduce — writing a file so that a failure never loses the earlier one.
//
// Every writer of the project (meshes, reports, Matrix Market files, the
// deformer cache) goes through AtomicFile:
//   * the bytes go to a temporary file beside the target
//     ("<dir>/.<name>.tmp.<pid>.<n>"), through a buffer;
//   * every write, the flush to disk (fsync) and the close are checked;
//   * commit() renames the temporary over the target (atomic on POSIX), so a
//     reader sees the old file or the new one, never a truncated one;
//   * anything else (an error, an exception, no commit) removes the
//     temporary: the earlier file is untouched and nothing is left behind.
// A target that exists and is not a regular file (/dev/null, /dev/full, a
// FIFO) cannot be replaced: it is written in place, still with every write
// and the close checked. A symbolic link is followed: the file it names is
// replaced, the link stays.
//
// Errors throw qpreduce::FileError "<path>: <problem>", the problem in words
// with the system's reason ("cannot write (No space left on device); the
// earlier file is unchanged"). A process that may exceed a file-size limit
// (RLIMIT_FSIZE) should ignore SIGXFSZ, so that the write fails with EFBIG
// instead of the signal ending the process and leaving the temporary.
#pragma once

#include <cstddef>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "qpreduce/util/file_error.h"

namespace qpreduce {

class AtomicFile {
 public:
  // Creates the temporary beside `path`. Throws FileError when the directory
  // is missing or not writable, or `path` is a directory.
  explicit AtomicFile(std::string path);
  // Without commit(): closes and removes the temporary; never throws.
  ~AtomicFile();
  AtomicFile(const AtomicFile&) = delete;
  AtomicFile& operator=(const AtomicFile&) = delete;

  // Appends `bytes` (buffered). Throws FileError when the system refuses.
  void write(const void* data, std::size_t bytes);
  void write(std::string_view text) { write(text.data(), text.size()); }

  // Flushes, syncs, closes and renames the temporary over the target.
  // Throws FileError (and removes the temporary) when any step fails.
  void commit();
  // The part of commit() that can fail for want of space: flushes, syncs
  // and closes; commit() then only renames. Lets several files be written
  // all together (write_files_atomically). Throws FileError (and removes
  // the temporary) when a step fails.
  void seal();

  const std::string& path() const { return path_; }
  // The temporary's path ("" when writing a non-regular target in place).
  const std::string& temporary() const { return temporary_; }

 private:
  void flush();
  void write_all(const char* data, std::size_t bytes);
  [[noreturn]] void fail(const std::string& problem, int error);
  void discard() noexcept;

  std::string path_;       // as the caller named it (for messages)
  std::string target_;     // what the rename replaces (a link's target)
  std::string temporary_;  // "" when writing in place
  std::vector<char> buffer_;
  int fd_ = -1;
  bool sealed_ = false;  // flushed, synced and closed; only the rename is left
  bool committed_ = false;
};

// Writes `bytes` to `path` through an AtomicFile.
void write_file_atomically(const std::string& path, std::string_view bytes);

// Writes a set of files that belong together (TetGen's .node/.ele/.face):
// every destination is checked and every temporary written, synced and
// closed before the first rename, so a failure to create or write any of
// them (a missing directory, a full disk, a file-size limit) leaves every
// earlier file untouched and no temporary. Only a failure of the renames
// themselves (rare: they need no space) can leave the files before it new
// and the rest old. `files`: (path, bytes) pairs. Throws FileError.
void write_files_atomically(const std::vector<std::pair<std::string, std::string_view>>& files);

// Checks, before a long run, that `path` can be written the way AtomicFile
// writes it: not a directory, its directory exists and is writable (or, for
// an existing non-regular file, the file itself is writable). Throws
// FileError "<path>: cannot write here: <reason>" otherwise. `what` names the
// output in the message ("--report", "the cache").
void check_destination(const std::string& path, const std::string& what);

}  // namespace qpreduce
