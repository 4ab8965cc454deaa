#include "run_files.h"

#include <qpreduce/util/file_error.h>

#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <cstdio>
#include <filesystem>
#include <string_view>
#include <system_error>

namespace qpr {

namespace fs = std::filesystem;

namespace {

// Files beside `staged` that share its stem: "<stem>.<ext>" for any ext
// other than its own (TetGen's .node, .ele, .face), as (path, ext) pairs.
std::vector<std::pair<fs::path, std::string>> siblings(const fs::path& staged) {
  std::vector<std::pair<fs::path, std::string>> out;
  const std::string stem = staged.stem().string() + ".";
  std::error_code ec;
  const fs::path dir = staged.has_parent_path() ? staged.parent_path() : fs::path(".");
  for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    const std::string name = it->path().filename().string();
    if (name.size() > stem.size() && name.compare(0, stem.size(), stem) == 0 && name != staged.filename().string())
      out.emplace_back(it->path(), name.substr(stem.size() - 1));
  }
  return out;
}

// Moves the staged file `from` to `to` as AtomicFile would have written it:
// through a symbolic link to the file it names (the link stays); into a
// target that exists and is not a regular file (/dev/full, a FIFO) by
// writing the bytes, every write checked. Throws qpreduce::FileError.
void put_in_place(const fs::path& from, const fs::path& to) {
  std::error_code ec;
  fs::path target = to;
  if (fs::is_symlink(fs::symlink_status(to, ec))) {
    const fs::path link = fs::read_symlink(to, ec);
    if (!ec) target = link.is_absolute() ? link : to.parent_path() / link;
  }
  const fs::file_status st = fs::status(target, ec);
  if (!ec && fs::exists(st) && !fs::is_regular_file(st)) {
    int error = 0;
    std::FILE* in = std::fopen(from.c_str(), "rb");
    if (in == nullptr) error = errno;
    std::FILE* out = in ? std::fopen(target.c_str(), "wb") : nullptr;
    if (in != nullptr && out == nullptr) error = errno;
    char buffer[1 << 16];
    for (std::size_t got = 0; error == 0 && (got = std::fread(buffer, 1, sizeof buffer, in)) > 0;)
      if (std::fwrite(buffer, 1, got, out) != got) error = errno;
    if (error == 0 && std::fflush(out) != 0) error = errno;
    if (out != nullptr && std::fclose(out) != 0 && error == 0) error = errno;
    if (in != nullptr) std::fclose(in);
    if (error != 0) throw qpreduce::FileError(to.string(), 0, std::string("cannot write (") + std::strerror(error) + ")");
    fs::remove(from, ec);
    return;
  }
  fs::rename(from, target, ec);
  if (ec) throw qpreduce::FileError(to.string(), 0, "cannot put the output in place: " + ec.message());
}

}  // namespace

std::string RunFiles::stage(const std::string& target) {
  std::error_code ec;
  const fs::file_status st = fs::status(target, ec);
  if (!ec && fs::exists(st) && !fs::is_regular_file(st)) return target;  // /dev/null, a FIFO: in place
  const fs::path t(target);
  const std::string name = ".qpr-run." + std::to_string(::getpid()) + "." + std::to_string(counter_++) + "." +
                           t.filename().string();
  const std::string staged = (t.has_parent_path() ? t.parent_path() / name : fs::path(name)).string();
  staged_.emplace_back(staged, target);
  return staged;
}

void RunFiles::create_directories(const std::string& dir) {
  std::vector<fs::path> missing;
  std::error_code ec;
  for (fs::path p = fs::path(dir).lexically_normal(); !p.empty() && !fs::exists(p, ec); p = p.parent_path()) {
    missing.push_back(p);
    if (p == p.parent_path()) break;
  }
  fs::create_directories(dir, ec);
  if (ec) throw qpreduce::FileError(dir, 0, "cannot create the directory: " + ec.message());
  for (auto it = missing.rbegin(); it != missing.rend(); ++it) created_.push_back(it->string());
}

void RunFiles::commit() {
  for (size_t i = 0; i < staged_.size(); ++i) {
    const auto& [staged, target] = staged_[i];
    std::error_code ec;
    if (staged == target || !fs::exists(staged, ec)) continue;  // written in place, or staged but never written
    const fs::path tstem = fs::path(target).parent_path() / fs::path(target).stem();
    try {
      for (const auto& [sibling, ext] : siblings(staged)) put_in_place(sibling, tstem.string() + ext);
      put_in_place(staged, target);
    } catch (const qpreduce::FileError&) {
      staged_.erase(staged_.begin(), staged_.begin() + static_cast<std::ptrdiff_t>(i));
      created_.clear();  // earlier outputs are already in them
      discard();
      throw;
    }
  }
  staged_.clear();
  created_.clear();
}

void RunFiles::discard() noexcept {
  for (const auto& [staged, target] : staged_) {
    std::error_code ec;
    if (staged == target) continue;
    for (const auto& [sibling, ext] : siblings(staged)) fs::remove(sibling, ec);
    fs::remove(staged, ec);
  }
  staged_.clear();
  for (auto it = created_.rbegin(); it != created_.rend(); ++it) {
    std::error_code ec;
    if (fs::is_empty(*it, ec) && !ec) fs::remove(*it, ec);
  }
  created_.clear();
}

std::string RunFiles::plain(std::string message) const {
  for (const auto& [staged, target] : staged_) {
    for (size_t at = message.find(staged); at != std::string::npos; at = message.find(staged, at + target.size()))
      message.replace(at, staged.size(), target);
  }
  return message;
}

RunFiles& run_files() {
  static RunFiles files;
  return files;
}

}  // namespace qpr
