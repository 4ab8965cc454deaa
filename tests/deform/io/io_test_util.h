// Helpers shared by the IO tests: a per-process temporary directory, small
// meshes with awkward coordinates, and the location of ../shared/data.
#pragma once

#include <catch2/catch.hpp>

#include "../../shared_data.h"

#include "qpreduce/deform/mesh/mesh.h"

#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <unistd.h>

namespace io_test {

namespace fs = std::filesystem;

// A fresh directory under the system temp dir, removed at scope exit. ctest
// runs test cases in parallel processes, so the name carries the pid.
class TempDir {
 public:
  TempDir() {
    static int counter = 0;
    path_ = fs::temp_directory_path() /
            ("qpreduce_deform_io_" + std::to_string(::getpid()) + "_" + std::to_string(counter++));
    fs::remove_all(path_);
    fs::create_directories(path_);
  }
  ~TempDir() {
    std::error_code ec;
    fs::remove_all(path_, ec);
  }
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;

  std::string path(const std::string& name) const { return (path_ / name).string(); }
  // Writes `content` byte for byte and returns the path.
  std::string write(const std::string& name, const std::string& content) const {
    std::ofstream out(path_ / name, std::ios::binary);
    out << content;
    return path(name);
  }

 private:
  fs::path path_;
};

// A file the test writes and the error message reading it must give.
struct Malformed {
  const char* name;
  std::string content;
  const char* message;
};

// Writes every case to `dir` and checks that read(path) throws a message
// containing the expected text.
template <typename Read>
void check_malformed(const TempDir& dir, Read read, const std::vector<Malformed>& cases) {
  for (const Malformed& c : cases) {
    INFO(c.name << ":\n" << c.content);
    CHECK_THROWS_WITH(read(dir.write(c.name, c.content)), Catch::Contains(c.message));
  }
}

// ../shared/data, or "" when it is absent (the data tests then skip).
inline std::string shared_data() { return qpreduce_test::shared_data(); }

// A closed octahedron (outward, counter-clockwise faces) with coordinates
// that do not print exactly in few digits.
inline qpreduce::deform::TriangleMesh awkward_octahedron() {
  qpreduce::deform::TriangleMesh m;
  m.V.resize(6, 3);
  m.V << 1.0 / 3.0, 0.0, 0.0,  //
      -0.1, 2.5e-7, 0.0,       //
      0.0, 123456.789, 1e-300,  //
      4.9406564584124654e-324, -7.0 / 11.0, 0.0,  //
      0.0, 0.0, 1e21,          //
      -0.0, 0.0, -3.0e-5 / 7.0;
  m.F.resize(8, 3);
  m.F << 0, 2, 4, 2, 1, 4, 1, 3, 4, 3, 0, 4, 2, 0, 5, 1, 2, 5, 3, 1, 5, 0, 3, 5;
  return m;
}

// Two positively oriented tetrahedra sharing a face, with their 6 boundary
// triangles.
inline qpreduce::deform::TetMesh two_tets() {
  qpreduce::deform::TetMesh m;
  m.V.resize(5, 3);
  m.V << 0.0, 0.0, 0.0,  //
      1.0, 0.0, 0.0,     //
      0.0, 1.0 / 3.0, 0.0,  //
      0.1, 0.2, 0.7,     //
      0.3, 0.3, -0.9;
  m.T.resize(2, 4);
  m.T << 0, 1, 2, 3,  //
      0, 2, 1, 4;
  m.F.resize(6, 3);
  m.F << 0, 1, 3, 1, 2, 3, 2, 0, 3, 0, 2, 4, 2, 1, 4, 1, 0, 4;
  return m;
}

}  // namespace io_test
