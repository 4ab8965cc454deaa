// AtomicFile: the earlier file survives every failure and no temporary stays
// behind (a full device, a file-size limit, a missing directory, an
// exception before commit).
#include <qpreduce/util/atomic_file.h>

#include "../file_size_limit.h"

#include <catch2/catch.hpp>

#include <filesystem>
#include <fstream>
#include <functional>
#include <sstream>
#include <string>

#include <unistd.h>

namespace fs = std::filesystem;
using qpreduce::AtomicFile;
using qpreduce::FileError;
using qpreduce_test::FileSizeLimit;

namespace {

// A fresh, empty directory for one test case.
fs::path scratch(const std::string& name) {
  const fs::path dir = fs::temp_directory_path() / ("qpreduce_atomic_" + name + "_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

std::string contents(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

// Every entry of `dir` but `keep`.
int others(const fs::path& dir, const std::string& keep) {
  int n = 0;
  for (const auto& e : fs::directory_iterator(dir)) n += e.path().filename() != keep;
  return n;
}

std::string message_of(const std::function<void()>& f) {
  try {
    f();
  } catch (const FileError& e) {
    return e.what();
  }
  return "";
}

}  // namespace

TEST_CASE("AtomicFile replaces the file on commit and keeps its permissions", "[atomic_file]") {
  const fs::path dir = scratch("commit");
  const fs::path target = dir / "a.txt";
  qpreduce::write_file_atomically(target.string(), "old\n");
  fs::permissions(target, fs::perms::owner_read | fs::perms::owner_write | fs::perms::group_read);
  qpreduce::write_file_atomically(target.string(), std::string(200000, 'x'));
  CHECK(contents(target) == std::string(200000, 'x'));
  CHECK(fs::status(target).permissions() == (fs::perms::owner_read | fs::perms::owner_write | fs::perms::group_read));
  CHECK(others(dir, "a.txt") == 0);
  fs::remove_all(dir);
}

TEST_CASE("AtomicFile without commit leaves the earlier file and no temporary", "[atomic_file]") {
  const fs::path dir = scratch("abandon");
  const fs::path target = dir / "a.txt";
  qpreduce::write_file_atomically(target.string(), "old\n");
  try {
    AtomicFile f(target.string());
    f.write(std::string(100000, 'y'));
    CHECK(fs::exists(f.temporary()));
    throw std::runtime_error("the run failed late");
  } catch (const std::runtime_error&) {
  }
  CHECK(contents(target) == "old\n");
  CHECK(others(dir, "a.txt") == 0);
  fs::remove_all(dir);
}

TEST_CASE("AtomicFile refuses a missing directory and a directory target", "[atomic_file]") {
  const fs::path dir = scratch("missing");
  const std::string missing = (dir / "no" / "a.txt").string();
  CHECK_THAT(message_of([&] { qpreduce::write_file_atomically(missing, "x"); }),
             Catch::Contains("does not exist") && Catch::Contains(missing));
  CHECK_THAT(message_of([&] { qpreduce::check_destination(missing, "report"); }),
             Catch::Contains("cannot write the report here") && Catch::Contains("does not exist"));
  CHECK_THAT(message_of([&] { qpreduce::write_file_atomically(dir.string(), "x"); }),
             Catch::Contains("is a directory"));
  CHECK(message_of([&] { qpreduce::check_destination((dir / "ok.txt").string(), "report"); }).empty());
  CHECK(others(dir, "") == 0);
  fs::remove_all(dir);
}

TEST_CASE("AtomicFile reports a full device as an error", "[atomic_file]") {
  if (!fs::exists("/dev/full")) return;
  CHECK_THAT(message_of([] { qpreduce::write_file_atomically("/dev/full", "x"); }),
             Catch::Contains("/dev/full") && Catch::Contains("No space left on device"));
  CHECK(message_of([] { qpreduce::write_file_atomically("/dev/null", "x"); }).empty());
}

TEST_CASE("AtomicFile under a file-size limit keeps the earlier file", "[atomic_file]") {
  const fs::path dir = scratch("limit");
  const fs::path target = dir / "a.txt";
  qpreduce::write_file_atomically(target.string(), "old\n");
  {
    const FileSizeLimit limit(4096);
    CHECK_THAT(message_of([&] { qpreduce::write_file_atomically(target.string(), std::string(100000, 'z')); }),
               Catch::Contains("File too large") && Catch::Contains("earlier file"));
  }
  CHECK(contents(target) == "old\n");
  CHECK(others(dir, "a.txt") == 0);
  fs::remove_all(dir);
}

TEST_CASE("AtomicFile through a symbolic link replaces the linked file", "[atomic_file]") {
  const fs::path dir = scratch("link");
  qpreduce::write_file_atomically((dir / "real.txt").string(), "old\n");
  fs::create_symlink("real.txt", dir / "link.txt");
  qpreduce::write_file_atomically((dir / "link.txt").string(), "new\n");
  CHECK(fs::is_symlink(dir / "link.txt"));
  CHECK(contents(dir / "real.txt") == "new\n");
  fs::remove_all(dir);
}

TEST_CASE("write_files_atomically writes a set of files all together or not at all", "[atomic_file]") {
  const fs::path dir = scratch("set");
  const std::string a = (dir / "m.node").string(), b = (dir / "m.ele").string();
  qpreduce::write_files_atomically({{a, "old node\n"}, {b, "old ele\n"}});
  CHECK(contents(a) == "old node\n");
  CHECK(contents(b) == "old ele\n");
  const std::string small(1000, 'n'), large(100000, 'e');
  {
    // The first file fits under the limit, the second does not: neither changes.
    const FileSizeLimit limit(4096);
    CHECK_THAT(message_of([&] { qpreduce::write_files_atomically({{a, small}, {b, large}}); }),
               Catch::Contains("m.ele") && Catch::Contains("File too large"));
  }
  CHECK(contents(a) == "old node\n");
  CHECK(contents(b) == "old ele\n");
  // A destination that cannot be written stops the set before anything is written.
  const std::string missing = (dir / "no" / "m.face").string();
  CHECK_THAT(message_of([&] { qpreduce::write_files_atomically({{a, small}, {b, small}, {missing, small}}); }),
             Catch::Contains("does not exist"));
  CHECK(contents(a) == "old node\n");
  CHECK(contents(b) == "old ele\n");
  CHECK(others(dir, "") == 2);  // m.node and m.ele, no temporary
  qpreduce::write_files_atomically({{a, small}, {b, large}});
  CHECK(contents(a) == small);
  CHECK(contents(b) == large);
  CHECK(others(dir, "") == 2);
  fs::remove_all(dir);
}

TEST_CASE("AtomicFile::seal leaves the rename to commit, and no temporary without it", "[atomic_file]") {
  const fs::path dir = scratch("seal");
  const fs::path target = dir / "a.txt";
  qpreduce::write_file_atomically(target.string(), "old\n");
  {
    AtomicFile f(target.string());
    f.write("new\n");
    f.seal();
    CHECK(contents(target) == "old\n");
    CHECK(contents(f.temporary()) == "new\n");
    CHECK_THROWS_AS(f.write("more"), FileError);
  }  // not committed: the sealed temporary goes
  CHECK(contents(target) == "old\n");
  CHECK(others(dir, "a.txt") == 0);
  AtomicFile g(target.string());
  g.write("new\n");
  g.seal();
  g.commit();
  CHECK(contents(target) == "new\n");
  CHECK_THROWS_AS(g.commit(), FileError);
  CHECK(others(dir, "a.txt") == 0);
  fs::remove_all(dir);
}
