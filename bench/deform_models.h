// The paper's Table 1 models as the deformation benchmarks use them
// (bench_deform, instruction_probe): where they are under the shared data,
// the paper's proxy counts, the 8 point handles of the on-site step and the
// frames' motion, and the precomputed-model cache. Bench-only.
//
// Models are looked up under $QPREDUCE_SHARED_DATA, else the source tree's
// ../shared/data (QPREDUCE_SHARED_DIR, a compile definition).
// QPREDUCE_BENCH_CACHE_DIR, when set, names a folder of precomputed models
// (<dir>/<Model>.qpr, written by Deformer::save when absent).
#pragma once

#include <qpreduce/deform/deformer/deformer.h>
#include <qpreduce/deform/io/mesh_io.h>
#include <qpreduce/deform/io/tet_io.h>
#include <qpreduce/deform/mesh/geometry.h>
#include <qpreduce/deform/proxies/proxies.h>

#include <fmt/format.h>

#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <stdexcept>
#include <string>
#include <system_error>

namespace qpreduce::bench {

struct ModelSpec {
  const char* name;
  const char* path;  // under the shared data folder
  Index linear, rotational;
};

// Table 1 of the paper: the models we have, with its proxy counts.
inline constexpr ModelSpec kModels[] = {
    {"Cylinder", "meshes/botsch-sorkine/cylinder.off", 33, 12},
    {"Cactus", "meshes/botsch-sorkine/cactus.off", 33, 27},
    {"Bar", "meshes/botsch-sorkine/bar.off", 33, 52},
    {"BumpyPlane", "meshes/botsch-sorkine/bumpy_plane.off", 33, 27},
    {"SolidCylinder", "tets/solid_cylinder.node", 33, 52},
    {"Tree", "paper-examples/tree/tree.off", 60, 60},
    {"Fertility", "tets/solid_fertility.node", 29, 26},
    {"Dinosaur", "paper-examples/dinosaur/dinosaur.off", 46, 34},
    {"Dragon", "paper-examples/dragon/dragon.off", 20, 20},
};

// Point handles of the on-site step: this many farthest-point vertices.
inline constexpr Index kHandles = 8;
// The frames move the first handle along a circle of this radius (a
// fraction of the bounding-box diagonal), in this many steps per turn back
// and forth, each this many radians apart.
inline constexpr double kMotionRadius = 0.1;
inline constexpr int kMotionSteps = 21;
inline constexpr double kMotionStepAngle = 0.3;

inline const ModelSpec* find_model(const std::string& name) {
  for (const ModelSpec& spec : kModels)
    if (name == spec.name) return &spec;
  return nullptr;
}

inline std::string shared_data_dir() {
  if (const char* env = std::getenv("QPREDUCE_SHARED_DATA")) return env;
  return std::string(QPREDUCE_SHARED_DIR) + "/data";
}

// The model's mesh (tetrahedra for .node/.mesh files, else triangles) with
// its Table 1 proxy counts and the paper's 8 rounds a frame in *options.
inline deform::DeformableMesh read_model(const ModelSpec& spec, deform::DeformerOptions* options) {
  options->iterations = 8;
  options->tolerance = 0.0;
  options->time_budget = 0.0;
  const std::string path = shared_data_dir() + "/" + spec.path;
  auto ends_with = [&](const char* tail) {
    const size_t n = std::strlen(tail);
    return path.size() >= n && path.compare(path.size() - n, n, tail) == 0;
  };
  deform::DeformableMesh model;
  if (ends_with(".node") || ends_with(".mesh")) {
    const deform::TetMesh m = deform::read_tet_mesh(path);
    model.V = m.V;
    model.T = m.T;
  } else {
    const deform::TriangleMesh m = deform::read_triangle_mesh(path);
    model.V = m.V;
    model.F = m.F;
  }
  options->linear_proxies = spec.linear;
  options->rotational_proxies = spec.rotational;
  return model;
}

// <QPREDUCE_BENCH_CACHE_DIR>/<name>.qpr, the folder made when missing; ""
// when the variable is unset or the folder cannot be made (no cache).
inline std::string cache_path(const ModelSpec& spec) {
  const char* dir = std::getenv("QPREDUCE_BENCH_CACHE_DIR");
  if (dir == nullptr || *dir == '\0') return {};
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) {
    fmt::print(stderr, "QPREDUCE_BENCH_CACHE_DIR={}: {}; precomputing without a cache\n", dir, ec.message());
    return {};
  }
  return std::string(dir) + "/" + spec.name + ".qpr";
}

// Loads the precomputed model from `cache` when it exists and loads, else
// precomputes it (and writes `cache` when given). Throws std::runtime_error
// when the precompute fails.
inline deform::PrecomputeSummary load_or_precompute(const ModelSpec& spec, const deform::DeformableMesh& model,
                                                    const deform::DeformerOptions& options, const std::string& cache,
                                                    deform::Deformer* deformer) {
  deform::PrecomputeSummary pre;
  bool loaded = false;
  if (!cache.empty() && std::filesystem::exists(cache)) {
    try {
      pre = deformer->load(cache, model, options);
      loaded = true;
    } catch (const std::exception& e) {  // e.g. a cache of an older format version: made again
      fmt::print(stderr, "{}: cache not loaded: {}\n", spec.name, e.what());
    }
  }
  if (!loaded) {
    pre = deformer->precompute(model, options);
    if (!cache.empty() && pre.ok()) deformer->save(cache);
  }
  if (!pre.ok()) throw std::runtime_error(std::string(spec.name) + ": " + pre.message);
  return pre;
}

// The on-site step's handles: kHandles well-spread single vertices
// (farthest-point samples), and their rest positions in *rest.
inline deform::Handles spread_handles(const deform::DeformableMesh& model, deform::Vertices* rest) {
  const deform::LinearProxies fps = model.is_tet()
                                        ? deform::linear_proxies_fps(model.V, deform::ElementsRef(model.T), kHandles)
                                        : deform::linear_proxies_fps(model.V, deform::ElementsRef(model.F), kHandles);
  deform::Handles handles;
  rest->resize(fps.count(), 3);
  for (Index h = 0; h < fps.count(); ++h) {
    handles.points.push_back({{fps.groups[h].front()}, {}});
    rest->row(h) = model.V.row(fps.groups[h].front());
  }
  return handles;
}

// Frame `frame`'s targets: the first handle moved along the circle
// (kMotionRadius of `diagonal`), the others at rest (warm start).
inline deform::HandleTargets moved_targets(const deform::Vertices& rest, double diagonal, int frame) {
  deform::HandleTargets t;
  t.points = rest;
  const double a = kMotionStepAngle * static_cast<double>(frame % kMotionSteps);
  t.points(0, 0) += kMotionRadius * diagonal * std::sin(a);
  t.points(0, 1) += kMotionRadius * diagonal * (1.0 - std::cos(a));
  return t;
}

}  // namespace qpreduce::bench
