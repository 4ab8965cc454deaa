// One libFuzzer binary for every reader; the environment variable
// QPR_FUZZ_TARGET names the reader it fuzzes (off, obj, ply, medit, tetgen,
// sel, def, id, anim, scene, mtx_sparse, mtx_dense, manifest, cache). Each
// input is written to a file with the reader's extension and read back: the
// reader may throw its documented errors (qpreduce::FileError and its
// IoError / MatrixMarketError, std::invalid_argument); anything else — a
// crash, a sanitizer report, another exception, an allocation past
// libFuzzer's -malloc_limit_mb — is a finding. scripts/fuzz.sh builds and
// runs it.
#include <qpreduce/deform/deformer/deformer.h>
#include <qpreduce/deform/io/handles_io.h>
#include <qpreduce/deform/io/json_keys.h>
#include <qpreduce/deform/io/mesh_io.h>
#include <qpreduce/deform/io/scene.h>
#include <qpreduce/deform/io/tet_io.h>
#include <qpreduce/deform/mesh/shapes.h>
#include <qpreduce/problems/matrix_market.h>
#include <qpreduce/util/file_error.h>

#include <algorithm>
#include <array>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <stdexcept>
#include <string>

#include <sys/stat.h>
#include <unistd.h>

namespace {

using namespace qpreduce;
using namespace qpreduce::deform;

constexpr std::array<const char*, 14> kReaders = {"off",        "obj",       "ply",      "medit", "tetgen",
                                                  "sel",        "def",       "id",       "anim",  "scene",
                                                  "mtx_sparse", "mtx_dense", "manifest", "cache"};
std::string reader;  // QPR_FUZZ_TARGET, checked by LLVMFuzzerInitialize

// A per-process scratch file "$QPR_FUZZ_TMP/qpr_fuzz_<pid>/input<ext>"
// (QPR_FUZZ_TMP defaults to /tmp; scripts/fuzz.sh points it to
// build-asan/fuzz/tmp and removes it afterwards).
std::string scratch(const char* ext) {
  static const std::string dir = [] {
    const char* root = std::getenv("QPR_FUZZ_TMP");
    const std::string d = std::string(root && *root ? root : "/tmp") + "/qpr_fuzz_" + std::to_string(::getpid());
    std::remove(d.c_str());
    (void)::mkdir(d.c_str(), 0700);
    return d;
  }();
  return dir + "/input" + ext;
}

void write(const std::string& path, const uint8_t* data, size_t size) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(size));
}

// The reader under test, on `path`.
void read_one(const uint8_t* data, size_t size) {
#define QPR_CASE(name, ext, call)          \
  if (reader == name) {                    \
    const std::string path = scratch(ext); \
    write(path, data, size);               \
    call;                                  \
    return;                                \
  }
  QPR_CASE("off", ".off", read_off(path))
  QPR_CASE("obj", ".obj", read_obj(path))
  QPR_CASE("ply", ".ply", read_ply(path))
  QPR_CASE("medit", ".mesh", read_medit(path))
  QPR_CASE("tetgen", ".node", {
    // The .node is the input; a fixed .ele with one tet names nodes 1–4.
    const std::string ele = scratch(".ele");
    const char* tet = "1 4 0\n1 1 2 3 4\n";
    write(ele, reinterpret_cast<const uint8_t*>(tet), std::char_traits<char>::length(tet));
    read_tetgen(path);
  })
  QPR_CASE("sel", ".sel", read_sel(path))
  QPR_CASE("def", ".def", read_def(path))
  QPR_CASE("id", ".id", read_id(path))
  QPR_CASE("anim", ".anim", read_anim(path))
  QPR_CASE("scene", ".json", {
    // Scenes name their mesh: a small OFF beside them ("m.off").
    const std::string mesh = path.substr(0, path.rfind('/')) + "/m.off";
    const char* off = "OFF\n4 2 0\n0 0 0\n1 0 0\n0 1 0\n1 1 0\n3 0 1 2\n3 1 3 2\n";
    write(mesh, reinterpret_cast<const uint8_t*>(off), std::char_traits<char>::length(off));
    read_scene(path);
  })
  QPR_CASE("mtx_sparse", ".mtx", read_market_sparse(path))
  QPR_CASE("mtx_dense", ".mtx", read_market_dense(path))
  QPR_CASE("manifest", ".json", {
    // `qpr qp --demands manifest.json` reads it with check_unique_json_keys
    // and nlohmann::json; the key check is the part of ours.
    std::string text(reinterpret_cast<const char*>(data), size);
    check_unique_json_keys(text, path);
  })
  QPR_CASE("cache", ".qpr", {
    // A cache must match its model: the loader checks the file before it
    // compares; the model here is a small cylinder.
    static const TriangleMesh m = shapes::capped_cylinder(0.5, 1.0, 6, 3);
    static const DeformableMesh model = [] {
      DeformableMesh d;
      d.V = m.V;
      d.F = m.F;
      return d;
    }();
    Deformer deformer;
    (void)deformer.load(path, model);
  })
#undef QPR_CASE
  __builtin_trap();  // not reached: LLVMFuzzerInitialize checked the name
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int* /*argc*/, char*** /*argv*/) {
  const char* name = std::getenv("QPR_FUZZ_TARGET");
  reader = name ? name : "";
  if (std::find_if(kReaders.begin(), kReaders.end(), [](const char* r) { return reader == r; }) == kReaders.end()) {
    std::string list;
    for (const char* r : kReaders) list += std::string(list.empty() ? "" : ", ") + r;
    std::fprintf(stderr, "fuzz_readers: set QPR_FUZZ_TARGET to one of %s (got '%s')\n", list.c_str(), reader.c_str());
    std::exit(2);
  }
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  try {
    read_one(data, size);
  } catch (const FileError&) {
  } catch (const std::invalid_argument&) {
  }
  return 0;
}
