// Writing through a temporary file renamed on success; see atomic_file.h.
#include "qpreduce/util/atomic_file.h"

#include <fmt/format.h>

#include <atomic>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <memory>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

namespace qpreduce {

namespace {

namespace fs = std::filesystem;

// Buffer size of the writes: large enough that the system calls do not show.
constexpr std::size_t kBufferBytes = std::size_t(1) << 16;

std::string reason(int error) { return std::strerror(error); }

// The directory a relative or absolute path lives in ("." for "a.txt").
std::string directory_of(const std::string& path) {
  const fs::path parent = fs::path(path).parent_path();
  return parent.empty() ? std::string(".") : parent.string();
}

// What a rename must replace: the file a symbolic link names, else `path`.
std::string resolve_link(const std::string& path) {
  std::error_code ec;
  if (!fs::is_symlink(fs::symlink_status(path, ec))) return path;
  const fs::path target = fs::weakly_canonical(path, ec);
  return ec ? path : target.string();
}

// "" when `path` can be written as AtomicFile writes it, else the reason.
std::string destination_problem(const std::string& path) {
  if (path.empty()) return "the path is empty";
  struct stat st {};
  const std::string target = resolve_link(path);
  if (::stat(target.c_str(), &st) == 0) {
    if (S_ISDIR(st.st_mode)) return "it is a directory";
    if (!S_ISREG(st.st_mode)) return ::access(target.c_str(), W_OK) == 0 ? "" : reason(errno);
  }
  const std::string dir = directory_of(target);
  if (::stat(dir.c_str(), &st) != 0) return fmt::format("the directory '{}' does not exist", dir);
  if (!S_ISDIR(st.st_mode)) return fmt::format("'{}' is not a directory", dir);
  if (::access(dir.c_str(), W_OK | X_OK) != 0) return fmt::format("the directory '{}': {}", dir, reason(errno));
  return "";
}

std::string temporary_name(const std::string& target) {
  static std::atomic<unsigned> counter{0};
  const fs::path p(target);
  const fs::path name = fmt::format(".{}.tmp.{}.{}", p.filename().string(), ::getpid(), counter++);
  return (p.parent_path() / name).string();
}

}  // namespace

AtomicFile::AtomicFile(std::string path) : path_(std::move(path)), target_(resolve_link(path_)) {
  const std::string problem = destination_problem(path_);
  if (!problem.empty()) throw FileError(path_, 0, "cannot write here: " + problem);
  struct stat st {};
  const bool exists = ::stat(target_.c_str(), &st) == 0;
  if (exists && !S_ISREG(st.st_mode)) {
    fd_ = ::open(target_.c_str(), O_WRONLY | O_CLOEXEC);
    if (fd_ < 0) throw FileError(path_, 0, "cannot open for writing (" + reason(errno) + ")");
  } else {
    temporary_ = temporary_name(target_);
    fd_ = ::open(temporary_.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0666);
    if (fd_ < 0) {
      const int error = errno;
      temporary_.clear();
      throw FileError(path_, 0, "cannot create a temporary file beside it (" + reason(error) + ")");
    }
    // The new file keeps the permissions of the one it replaces.
    if (exists) (void)::fchmod(fd_, st.st_mode & 07777);
  }
  buffer_.reserve(kBufferBytes);
}

AtomicFile::~AtomicFile() {
  if (!committed_) discard();
}

void AtomicFile::discard() noexcept {
  if (fd_ >= 0) ::close(fd_);
  fd_ = -1;
  if (!temporary_.empty()) ::unlink(temporary_.c_str());
  temporary_.clear();
}

void AtomicFile::fail(const std::string& problem, int error) {
  const bool in_place = temporary_.empty();
  discard();
  throw FileError(
      path_, 0,
      fmt::format("{} ({}){}", problem, reason(error), in_place ? "" : "; the earlier file, if any, is unchanged"));
}

void AtomicFile::write(const void* data, std::size_t bytes) {
  if (fd_ < 0) throw FileError(path_, 0, "write after the file was committed or discarded");
  const char* p = static_cast<const char*>(data);
  if (buffer_.size() + bytes > kBufferBytes) flush();
  if (bytes >= kBufferBytes) {
    write_all(p, bytes);  // a large block goes out directly, not through the buffer
    return;
  }
  buffer_.insert(buffer_.end(), p, p + bytes);
}

void AtomicFile::write_all(const char* data, std::size_t bytes) {
  std::size_t done = 0;
  while (done < bytes) {
    const ssize_t n = ::write(fd_, data + done, bytes - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) fail("cannot write", n < 0 ? errno : EIO);
    done += static_cast<std::size_t>(n);
  }
}

void AtomicFile::flush() {
  write_all(buffer_.data(), buffer_.size());
  buffer_.clear();
}

void AtomicFile::seal() {
  if (sealed_) return;
  if (fd_ < 0) throw FileError(path_, 0, "commit after the file was committed or discarded");
  flush();
  if (!temporary_.empty() && ::fsync(fd_) != 0) fail("cannot write to disk", errno);
  const int fd = fd_;
  fd_ = -1;
  if (::close(fd) != 0) fail("cannot close", errno);
  sealed_ = true;
}

void AtomicFile::commit() {
  if (committed_) throw FileError(path_, 0, "commit after the file was committed or discarded");
  seal();
  if (!temporary_.empty() && std::rename(temporary_.c_str(), target_.c_str()) != 0)
    fail("cannot replace the file with the new one", errno);
  temporary_.clear();
  committed_ = true;
}

void write_file_atomically(const std::string& path, std::string_view bytes) {
  AtomicFile file(path);
  file.write(bytes);
  file.commit();
}

void write_files_atomically(const std::vector<std::pair<std::string, std::string_view>>& files) {
  std::vector<std::unique_ptr<AtomicFile>> open;
  open.reserve(files.size());
  for (const auto& f : files) open.push_back(std::make_unique<AtomicFile>(f.first));  // every destination first
  for (size_t i = 0; i < files.size(); ++i) open[i]->write(files[i].second);
  for (auto& f : open) f->seal();
  for (auto& f : open) f->commit();  // renames only
}

void check_destination(const std::string& path, const std::string& what) {
  const std::string problem = destination_problem(path);
  if (!problem.empty()) throw FileError(path, 0, fmt::format("cannot write the {} here: {}", what, problem));
}

}  // namespace qpreduce
