// The JSON scene reader; the schema is in docs/formats.md ("JSON scene").
#include "qpreduce/deform/io/scene.h"

#include "qpreduce/deform/io/json_keys.h"
#include "qpreduce/deform/io/mesh_io.h"
#include "qpreduce/deform/io/tet_io.h"

#include "format_common.h"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cassert>
#include <cmath>
#include <filesystem>
#include <initializer_list>
#include <map>

namespace qpreduce::deform {

Index SceneHandle::points() const { return is_group() ? 1 : static_cast<Index>(vertices.size()); }

Index SceneHandle::frames() const {
  return static_cast<Index>(std::max(targets.size(), transforms.size()));
}

Vertices SceneHandle::targets_at(Index frame, const Vertices& rest) const {
  assert(frames() > 0);
  const std::size_t f = static_cast<std::size_t>(std::min(frame, frames() - 1));
  if (!targets.empty()) return targets[f];
  const Eigen::Matrix4d& M = transforms[f];
  Vertices P(points(), 3);
  if (is_group()) {
    Eigen::RowVector3d p = Eigen::RowVector3d::Zero();
    for (std::size_t i = 0; i < vertices.size(); ++i) p += weights[i] * rest.row(vertices[i]);
    P.row(0) = p;
  } else {
    for (std::size_t i = 0; i < vertices.size(); ++i) P.row(static_cast<Index>(i)) = rest.row(vertices[i]);
  }
  // p ↦ A·p + t for every row p.
  return (P * M.topLeftCorner<3, 3>().transpose()).rowwise() + M.topRightCorner<3, 1>().transpose();
}

namespace {

using json = nlohmann::json;

class SceneParser {
 public:
  explicit SceneParser(const std::string& path)
      : path_(path), dir_(std::filesystem::path(path).parent_path()) {}

  // The scene file's JSON, or IoError.
  json root() const {
    const std::string text = detail::read_file(path_);
    try {
      check_unique_json_keys(text, path_);
      return json::parse(text);
    } catch (const json::parse_error& e) {
      detail::fail(path_, 0, fmt::format("JSON syntax error: {}", e.what()));
    } catch (const json::exception& e) {
      // out_of_range 406: a number too large for a double (1e400).
      detail::fail(path_, 0, fmt::format("JSON value out of range: {}", e.what()));
    }
  }

  // A path as the scene names it, resolved against the scene's folder.
  std::string resolved(const std::string& given) const {
    const std::filesystem::path p(given);
    return (p.is_absolute() ? p : dir_ / p).lexically_normal().string();
  }

  // The strings the schema reads as paths (/mesh, a proxy's file, a patch's
  // or handle's sel/file, id/file, def and anim), from the JSON alone.
  std::vector<SceneFile> named_files() const {
    std::vector<SceneFile> out;
    const json r = root();
    if (!r.is_object()) return out;
    if (r.contains("mesh") && r["mesh"].is_string()) out.push_back({"/mesh", resolved(r["mesh"])});
    if (r.contains("proxies") && r["proxies"].is_object())
      for (const auto& item : r["proxies"].items())
        if (item.value().is_string()) out.push_back({"/proxies/" + item.key(), resolved(item.value())});
    for (const char* list : {"patches", "handles"}) {
      if (!r.contains(list) || !r[list].is_array()) continue;
      for (std::size_t i = 0; i < r[list].size(); ++i) {
        const json& entry = r[list][i];
        if (!entry.is_object()) continue;
        const std::string at = fmt::format("/{}/{}", list, i);
        for (const char* key : {"def", "anim"})
          if (entry.contains(key) && entry[key].is_string()) out.push_back({at + "/" + key, resolved(entry[key])});
        for (const char* key : {"sel", "id"})
          if (entry.contains(key) && entry[key].is_object() && entry[key].contains("file") &&
              entry[key]["file"].is_string())
            out.push_back({at + "/" + key + "/file", resolved(entry[key]["file"])});
      }
    }
    return out;
  }

  Scene parse() {
    const json root = this->root();
    if (!root.is_object()) fail("", "the scene must be a JSON object");
    check_keys(root, "", {"description", "mesh", "energy", "solver", "proxies", "patches", "handles"});
    Scene s;
    s.source = path_;
    load_mesh(member(root, "", "mesh"), s);
    n_ = s.vertex_count();
    if (root.contains("energy")) parse_energy(root["energy"], s);
    if (root.contains("solver")) parse_solver(root["solver"], s);
    if (root.contains("proxies")) parse_proxies(root["proxies"], s);
    if (root.contains("patches")) {
      const json& patches = array(root["patches"], "/patches");
      for (std::size_t i = 0; i < patches.size(); ++i)
        s.patches.push_back(parse_patch(patches[i], fmt::format("/patches/{}", i)));
    }
    if (root.contains("handles")) {
      const json& handles = array(root["handles"], "/handles");
      for (std::size_t i = 0; i < handles.size(); ++i) parse_handle(handles[i], fmt::format("/handles/{}", i), s);
    }
    check_frames(s);
    s.files = std::move(files_);
    return s;
  }

 private:
  [[noreturn]] void fail(const std::string& where, const std::string& problem) const {
    detail::fail(path_, 0, where.empty() ? problem : fmt::format("{}: {}", where, problem));
  }

  void check_keys(const json& obj, const std::string& where, std::initializer_list<const char*> allowed) const {
    if (!obj.is_object()) fail(where, "expected a JSON object");
    for (const auto& item : obj.items())
      if (std::none_of(allowed.begin(), allowed.end(), [&](const char* a) { return item.key() == a; }))
        fail(where, fmt::format("unknown key '{}'", item.key()));
  }
  const json& member(const json& obj, const std::string& where, const char* key) const {
    if (!obj.contains(key)) fail(where.empty() ? "/" : where, fmt::format("missing key '{}'", key));
    return obj[key];
  }
  const json& array(const json& j, const std::string& where) const {
    if (!j.is_array()) fail(where, "expected an array");
    return j;
  }
  double number(const json& j, const std::string& where) const {
    if (!j.is_number()) fail(where, "expected a number");
    const double v = j.get<double>();
    if (!std::isfinite(v)) fail(where, "expected a finite number");
    return v;
  }
  long long integer(const json& j, const std::string& where) const {
    if (!j.is_number_integer()) fail(where, "expected an integer");
    if (j.is_number_unsigned() && j.get<unsigned long long>() > std::numeric_limits<int>::max())
      fail(where, "integer too large");
    return j.get<long long>();
  }
  int vertex(const json& j, const std::string& where) const {
    const long long v = integer(j, where);
    if (v < 0 || v >= n_) fail(where, fmt::format("vertex {} out of range (the mesh has {} vertices)", v, n_));
    return static_cast<int>(v);
  }
  std::string file(const json& j, const std::string& where) {
    if (!j.is_string() || j.get<std::string>().empty()) fail(where, "expected a file path");
    std::string path = resolved(j.get<std::string>());
    files_.push_back({where, path});
    return path;
  }
  std::vector<double> numbers(const json& j, const std::string& where, std::size_t count) const {
    if (!j.is_array() || j.size() != count)
      fail(where, fmt::format("expected {} numbers, got {}", count, j.is_array() ? j.size() : 1));
    std::vector<double> out;
    for (std::size_t i = 0; i < count; ++i) out.push_back(number(j[i], fmt::format("{}/{}", where, i)));
    return out;
  }
  Eigen::Matrix4d transform(const json& j, const std::string& where) const {
    // 16 numbers, row-major, or 4 rows of 4.
    std::vector<double> a;
    if (j.is_array() && j.size() == 4 && j[0].is_array()) {
      for (std::size_t r = 0; r < 4; ++r) {
        const std::vector<double> row = numbers(j[r], fmt::format("{}/{}", where, r), 4);
        a.insert(a.end(), row.begin(), row.end());
      }
    } else {
      a = numbers(j, where, 16);
    }
    const Eigen::Matrix4d M = Eigen::Map<const Eigen::Matrix<double, 4, 4, Eigen::RowMajor>>(a.data());
    if (M.row(3) != Eigen::RowVector4d(0.0, 0.0, 0.0, 1.0))
      fail(where, "the last row of a transform must be 0 0 0 1 (an affine map)");
    return M;
  }

  void load_mesh(const json& j, Scene& s) {
    s.mesh_path = file(j, "/mesh");
    const std::string ext = detail::lower_extension(s.mesh_path);
    s.is_tet = ext == ".mesh" || ext == ".node" || ext == ".ele";
    if (s.is_tet)
      s.solid = read_tet_mesh(s.mesh_path);
    else
      s.surface = read_triangle_mesh(s.mesh_path);
  }

  void parse_energy(const json& j, Scene& s) const {
    check_keys(j, "/energy", {"alpha", "beta", "gamma", "model", "psi"});
    if (j.contains("model")) {
      if (!j["model"].is_string() || (j["model"] != "arap" && j["model"] != "conformal")) {
        fail("/energy/model", "expected \"arap\" or \"conformal\"");
      }
      s.model = j["model"].get<std::string>();
    }
    if (j.contains("psi")) {
      const double v = number(j["psi"], "/energy/psi");
      if (!(v > 1.0)) fail("/energy/psi", "must be > 1 (scales within [1/psi, psi])");
      s.psi = v;
    }
    const std::pair<const char*, std::optional<double>*> fields[] = {
        {"alpha", &s.alpha}, {"beta", &s.beta}, {"gamma", &s.gamma}};
    for (const auto& [key, out] : fields) {
      if (!j.contains(key)) continue;
      const double v = number(j[key], fmt::format("/energy/{}", key));
      if (v < 0.0) fail(fmt::format("/energy/{}", key), "must be >= 0");
      *out = v;
    }
  }

  void parse_solver(const json& j, Scene& s) const {
    check_keys(j, "/solver", {"iterations", "constraints", "delta"});
    if (j.contains("iterations")) {
      const long long it = integer(j["iterations"], "/solver/iterations");
      if (it < 0 || it > std::numeric_limits<int>::max()) fail("/solver/iterations", "must be >= 0");
      s.iterations = static_cast<int>(it);
    }
    if (j.contains("constraints")) {
      const json& c = j["constraints"];
      if (c == "hard")
        s.constraints = ConstraintMode::Hard;
      else if (c == "soft")
        s.constraints = ConstraintMode::Soft;
      else
        fail("/solver/constraints", "expected \"hard\" or \"soft\"");
    }
    if (j.contains("delta")) {
      const double d = number(j["delta"], "/solver/delta");
      if (d <= 0.0) fail("/solver/delta", "must be > 0");
      s.delta = d;
    }
  }

  void parse_proxies(const json& j, Scene& s) {
    check_keys(j, "/proxies", {"linear", "rotational", "affine"});
    const std::pair<const char*, ProxySpec*> fields[] = {
        {"linear", &s.linear_proxies}, {"rotational", &s.rotational_clusters}, {"affine", &s.affine_patches}};
    for (const auto& [key, spec] : fields) {
      if (!j.contains(key)) continue;
      const std::string where = fmt::format("/proxies/{}", key);
      const json& v = j[key];
      if (v.is_number()) {
        if (std::string(key) == "affine") fail(where, "affine patches are given by an .id file, not a count");
        const long long count = integer(v, where);
        if (count < 1) fail(where, "a proxy count must be >= 1");
        spec->count = static_cast<Index>(count);
        continue;
      }
      spec->id_file = file(v, where);
      const VertexIds& ids = id_file(spec->id_file);
      spec->groups = std::string(key) == "linear"       ? linear_groups_from_ids(ids)
                     : std::string(key) == "rotational" ? rotation_groups_from_ids(ids)
                                                        : affine_patches_from_ids(ids);
      spec->count = spec->groups.size();
    }
  }

  // Each .sel/.id file is read and checked against the mesh once.
  template <typename T, typename Read>
  const T& cached(std::map<std::string, T>& cache, const std::string& path, Read read) const {
    auto it = cache.find(path);
    if (it == cache.end()) {
      it = cache.emplace(path, read(path)).first;
      it->second.validate(n_);
    }
    return it->second;
  }
  const Selection& sel_file(const std::string& path) { return cached(sels_, path, read_sel); }
  const VertexIds& id_file(const std::string& path) { return cached(ids_, path, read_id); }

  // "vertices": [...], "sel": {"file", "role"} or "id": {"file", "value"}.
  std::vector<int> vertex_set(const json& j, const std::string& where) {
    std::vector<int> out;
    if (j.contains("vertices")) {
      const json& list = array(j["vertices"], where + "/vertices");
      for (std::size_t i = 0; i < list.size(); ++i) out.push_back(vertex(list[i], fmt::format("{}/vertices/{}", where, i)));
      std::vector<int> sorted = out;
      std::sort(sorted.begin(), sorted.end());
      if (std::adjacent_find(sorted.begin(), sorted.end()) != sorted.end())
        fail(where + "/vertices", "a vertex is listed twice");
    } else if (j.contains("sel")) {
      const std::string at = where + "/sel";
      check_keys(j["sel"], at, {"file", "role"});
      const Selection& sel = sel_file(file(member(j["sel"], at, "file"), at + "/file"));
      const json& role = member(j["sel"], at, "role");
      const char* names[3] = {"fixed", "free", "handle"};
      int r = -1;
      for (int k = 0; k < 3; ++k)
        if (role == names[k] || role == k) r = k;
      if (r < 0) fail(at + "/role", "expected \"fixed\", \"free\", \"handle\" or 0, 1, 2");
      out = sel.vertices(static_cast<SelRole>(r));
    } else if (j.contains("id")) {
      const std::string at = where + "/id";
      check_keys(j["id"], at, {"file", "value"});
      const VertexIds& ids = id_file(file(member(j["id"], at, "file"), at + "/file"));
      const long long value = integer(member(j["id"], at, "value"), at + "/value");
      for (std::size_t v = 0; v < ids.ids.size(); ++v)
        if (ids.ids[v] == value) out.push_back(static_cast<int>(v));
    } else {
      fail(where, "expected one of 'vertices', 'sel', 'id'");
    }
    if (out.empty()) fail(where, "selects no vertex");
    return out;
  }

  static int count_keys(const json& j, std::initializer_list<const char*> keys) {
    return static_cast<int>(std::count_if(keys.begin(), keys.end(), [&](const char* k) { return j.contains(k); }));
  }

  ScenePatch parse_patch(const json& j, const std::string& where) {
    check_keys(j, where, {"type", "vertices", "sel", "id"});
    if (count_keys(j, {"vertices", "sel", "id"}) != 1) fail(where, "expected exactly one of 'vertices', 'sel', 'id'");
    ScenePatch p;
    const json& type = member(j, where, "type");
    if (type == "fixed")
      p.type = PatchType::Fixed;
    else if (type == "rigid")
      p.type = PatchType::Rigid;
    else if (type == "affine")
      p.type = PatchType::Affine;
    else
      fail(where + "/type", "expected \"fixed\", \"rigid\" or \"affine\"");
    p.vertices = vertex_set(j, where);
    std::sort(p.vertices.begin(), p.vertices.end());
    return p;
  }

  void parse_handle(const json& j, const std::string& where, Scene& s) {
    if (j.is_object() && j.contains("anim")) {
      check_keys(j, where, {"anim", "name"});
      expand_anim(j, where, s);
      return;
    }
    check_keys(j, where, {"name", "vertices", "sel", "id", "group", "targets", "transforms", "def"});
    if (count_keys(j, {"vertices", "sel", "id", "group"}) != 1)
      fail(where, "expected exactly one of 'vertices', 'sel', 'id', 'group'");
    if (count_keys(j, {"targets", "transforms", "def"}) != 1)
      fail(where, "expected exactly one of 'targets', 'transforms', 'def'");
    SceneHandle h;
    if (j.contains("name")) {
      if (!j["name"].is_string()) fail(where + "/name", "expected a string");
      h.name = j["name"].get<std::string>();
    }
    if (j.contains("group")) {
      const json& group = array(j["group"], where + "/group");
      if (group.empty()) fail(where + "/group", "selects no vertex");
      for (std::size_t i = 0; i < group.size(); ++i) {
        const std::string at = fmt::format("{}/group/{}", where, i);
        if (!group[i].is_array() || group[i].size() != 2) fail(at, "expected a pair [vertex, weight]");
        h.vertices.push_back(vertex(group[i][0], at + "/0"));
        h.weights.push_back(number(group[i][1], at + "/1"));
      }
      if (std::all_of(h.weights.begin(), h.weights.end(), [](double w) { return w == 0.0; }))
        fail(where + "/group", "every weight is 0: the handle would hold no point");
    } else {
      h.vertices = vertex_set(j, where);
    }
    if (j.contains("def")) {
      h.transforms.push_back(read_def(file(j["def"], where + "/def")));
    } else if (j.contains("transforms")) {
      const json& frames = array(j["transforms"], where + "/transforms");
      for (std::size_t f = 0; f < frames.size(); ++f)
        h.transforms.push_back(transform(frames[f], fmt::format("{}/transforms/{}", where, f)));
    } else {
      const json& frames = array(j["targets"], where + "/targets");
      for (std::size_t f = 0; f < frames.size(); ++f)
        h.targets.push_back(target_frame(frames[f], fmt::format("{}/targets/{}", where, f), h));
    }
    if (h.frames() == 0) fail(where, "no frames (an empty list of targets or transforms)");
    s.handles.push_back(std::move(h));
    handle_where_.push_back(where);
  }

  // A group's frame is one point [x, y, z]; a vertex list's is one point per vertex.
  Vertices target_frame(const json& j, const std::string& where, const SceneHandle& h) const {
    Vertices P(h.points(), 3);
    if (h.is_group()) {
      const std::vector<double> p = numbers(j, where, 3);
      P.row(0) << p[0], p[1], p[2];
      return P;
    }
    if (!j.is_array() || static_cast<Index>(j.size()) != h.points())
      fail(where, fmt::format("expected {} points (one per handle vertex), got {}", h.points(),
                              j.is_array() ? j.size() : 1));
    for (std::size_t i = 0; i < j.size(); ++i) {
      const std::vector<double> p = numbers(j[i], fmt::format("{}/{}", where, i), 3);
      P.row(static_cast<Index>(i)) << p[0], p[1], p[2];
    }
    return P;
  }

  // One weighted-group handle per row of the .anim file.
  void expand_anim(const json& j, const std::string& where, Scene& s) {
    const HandleAnimation anim = read_anim(file(j["anim"], where + "/anim"));
    anim.validate(n_);
    if (anim.targets.empty()) fail(where + "/anim", "the .anim file has no point lists (no targets)");
    std::string name = "anim";
    if (j.contains("name")) {
      if (!j["name"].is_string()) fail(where + "/name", "expected a string");
      name = j["name"].get<std::string>();
    }
    const Eigen::SparseMatrix<double, Eigen::RowMajor> W = anim.weights;
    for (Index r = 0; r < W.rows(); ++r) {
      SceneHandle h;
      h.name = fmt::format("{}[{}]", name, r);
      for (Eigen::SparseMatrix<double, Eigen::RowMajor>::InnerIterator it(W, r); it; ++it) {
        h.vertices.push_back(static_cast<int>(it.col()));
        h.weights.push_back(it.value());
      }
      for (const Vertices& frame : anim.targets) h.targets.push_back(frame.row(r));
      s.handles.push_back(std::move(h));
      handle_where_.push_back(where);
    }
  }

  void check_frames(Scene& s) const {
    for (const SceneHandle& h : s.handles) s.frames = std::max(s.frames, h.frames());
    for (std::size_t i = 0; i < s.handles.size(); ++i) {
      const Index f = s.handles[i].frames();
      if (f != 1 && f != s.frames)
        fail(handle_where_[i],
             fmt::format("{} frames, but another handle has {} (a handle has 1 frame or as many as the scene)", f,
                         s.frames));
    }
  }

  std::string path_;
  std::filesystem::path dir_;
  Index n_ = 0;
  std::map<std::string, Selection> sels_;
  std::map<std::string, VertexIds> ids_;
  std::vector<std::string> handle_where_;  // JSON pointer of each entry of Scene::handles
  std::vector<SceneFile> files_;           // every path file() resolved, in order
};

}  // namespace

Scene read_scene(const std::string& path) { return SceneParser(path).parse(); }

std::vector<SceneFile> scene_files(const std::string& path) { return SceneParser(path).named_files(); }

}  // namespace qpreduce::deform
