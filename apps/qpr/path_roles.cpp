#include "path_roles.h"

#include <qpreduce/deform/deformer/cache_file.h>
#include <qpreduce/deform/io/scene.h>

#include <CLI/CLI.hpp>
#include <fmt/format.h>

#include <sys/stat.h>

#include <cctype>
#include <filesystem>
#include <map>
#include <optional>
#include <stdexcept>
#include <utility>

namespace qpr {

namespace {

namespace fs = std::filesystem;

// How a path is compared: the (device, inode) of an existing file (links
// resolved), else its absolute, normalised form with symbolic links of the
// existing part resolved.
struct Identity {
  bool exists = false;
  bool regular = false;
  bool directory = false;
  dev_t device = 0;
  ino_t inode = 0;
  fs::path canonical;
};

Identity identity(const std::string& path) {
  Identity id;
  struct stat st {};
  if (::stat(path.c_str(), &st) == 0) {
    id.exists = true;
    id.regular = S_ISREG(st.st_mode);
    id.directory = S_ISDIR(st.st_mode);
    id.device = st.st_dev;
    id.inode = st.st_ino;
  }
  std::error_code ec;
  id.canonical = fs::weakly_canonical(fs::absolute(path, ec), ec);
  if (ec) id.canonical = fs::path(path).lexically_normal();
  return id;
}

bool same_file(const Identity& a, const Identity& b) {
  if (a.exists && b.exists) return a.device == b.device && a.inode == b.inode;
  return a.canonical == b.canonical;
}

bool writes(PathRole role) { return role != PathRole::Input && role != PathRole::Scene; }

// The extension of a TetGen file, lower case, or "".
std::string tetgen_extension(const std::string& path) {
  std::string ext = fs::path(path).extension().string();
  for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return ext == ".node" || ext == ".ele" || ext == ".face" ? ext : std::string();
}

// `given` and, for a TetGen path of an input or an output, its siblings.
void add_with_tetgen_set(const RolePath& given, std::vector<RolePath>* out) {
  out->push_back(given);
  const std::string ext = tetgen_extension(given.path);
  if (ext.empty() || (given.role != PathRole::Input && given.role != PathRole::Output)) return;
  const std::string prefix = given.path.substr(0, given.path.size() - ext.size());
  for (const char* sibling : {".node", ".ele", ".face"}) {
    if (ext == sibling) continue;
    std::error_code ec;  // an input's absent sibling is not read
    if (given.role == PathRole::Input && !fs::exists(prefix + sibling, ec)) continue;
    out->push_back({fmt::format("{} (its {})", given.option, sibling), prefix + sibling, given.role});
  }
}

const char* role_word(PathRole role) {
  switch (role) {
    case PathRole::Input: return "input";
    case PathRole::Scene: return "scene";
    case PathRole::Output: return "output";
    case PathRole::OutputDirectory: return "output folder";
    case PathRole::Cache: return "cache";
  }
  return "path";
}

std::map<std::string, std::vector<std::pair<CLI::Option*, PathRole>>>& registry() {
  static std::map<std::string, std::vector<std::pair<CLI::Option*, PathRole>>> options;
  return options;
}

}  // namespace

CLI::Option* path_role(CLI::App* command, CLI::Option* option, PathRole role) {
  registry()[command->get_name()].emplace_back(option, role);
  return option;
}

std::vector<RolePath> files_of(const RolePath& given) {
  std::vector<RolePath> out;
  if (given.role != PathRole::Scene || given.path.empty()) {
    add_with_tetgen_set(given, &out);
    return out;
  }
  out.push_back(given);
  for (const qpreduce::deform::SceneFile& f : qpreduce::deform::scene_files(given.path))
    add_with_tetgen_set({fmt::format("{}'s {}", given.option, f.where), f.path, PathRole::Input}, &out);
  return out;
}

void check_path_roles(const std::vector<RolePath>& given) {
  std::vector<RolePath> paths;
  for (const RolePath& p : given) {
    const std::vector<RolePath> files = files_of(p);
    paths.insert(paths.end(), files.begin(), files.end());
  }
  std::vector<std::optional<Identity>> ids;
  ids.reserve(paths.size());
  for (const RolePath& p : paths) {
    if (p.path.empty()) {
      ids.emplace_back();
      continue;
    }
    Identity id = identity(p.path);
    // /dev/null, a FIFO, a terminal: written in place, never a clash.
    if (id.exists && !id.regular && !id.directory) {
      ids.emplace_back();
      continue;
    }
    ids.emplace_back(std::move(id));
  }
  for (std::size_t i = 0; i < paths.size(); ++i) {
    if (!ids[i] || !writes(paths[i].role)) continue;
    for (std::size_t j = 0; j < paths.size(); ++j) {
      if (j == i || !ids[j] || (writes(paths[j].role) && j < i)) continue;  // each pair of writers once
      if (!same_file(*ids[i], *ids[j])) continue;
      const std::string which = paths[i].path == paths[j].path
                                    ? paths[i].path
                                    : fmt::format("{} and {} are one file", paths[i].path, paths[j].path);
      const std::string what = writes(paths[j].role)
                                   ? std::string("one output would overwrite the other")
                                   : fmt::format("the {} would replace the input", role_word(paths[i].role));
      // Inputs first ("MESH and --out"), outputs in their order ("--out and --report").
      const RolePath& first = writes(paths[j].role) ? paths[i] : paths[j];
      const RolePath& second = writes(paths[j].role) ? paths[j] : paths[i];
      throw std::invalid_argument(fmt::format("{} and {} name the same file ({}): {}; choose another path for {}",
                                              first.option, second.option, which, what, second.option));
    }
  }
  for (const RolePath& p : paths) {
    if (p.role == PathRole::Cache && !p.path.empty() && !qpreduce::deform::may_replace_with_cache(p.path)) {
      throw std::invalid_argument(
          fmt::format("{}: {} exists and is not a qpreduce cache; refusing to "
                      "replace it (remove it or choose another path)",
                      p.option, p.path));
    }
  }
}

std::vector<RolePath> given_paths(const std::string& command) {
  std::vector<RolePath> paths;
  for (const auto& [option, role] : registry()[command]) {
    if (option->count() == 0) continue;
    for (const std::string& value : option->results()) {
      // A positional (the mesh) by its upper-case name, as in the usage line.
      std::string name = option->get_name(false, true);
      if (option->get_positional()) {
        for (char& c : name) c = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
      }
      paths.push_back({std::move(name), value, role});
    }
  }
  return paths;
}

void check_path_roles(const std::string& command, const std::vector<RolePath>& extra) {
  std::vector<RolePath> paths = given_paths(command);
  paths.insert(paths.end(), extra.begin(), extra.end());
  check_path_roles(paths);
}

}  // namespace qpr
