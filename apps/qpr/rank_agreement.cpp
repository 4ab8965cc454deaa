#include "rank_agreement.h"

#include "path_roles.h"

#include <CLI/CLI.hpp>
#include <fmt/format.h>
#include <fmt/ranges.h>

#include <algorithm>
#include <exception>
#include <filesystem>
#include <fstream>
#include <map>

namespace qpr {

namespace {

// 64-bit FNV-1a.
struct Fnv {
  std::uint64_t h = 1469598103934665603ull;
  void add(const char* data, std::size_t n) {
    for (std::size_t i = 0; i < n; ++i) {
      h ^= static_cast<unsigned char>(data[i]);
      h *= 1099511628211ull;
    }
  }
  void add(const std::string& s) {
    add(s.data(), s.size());
    add("\0", 1);
  }
};

void add_file(Fnv* f, const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    f->add("<unreadable>");
    return;
  }
  char buffer[1 << 16];
  while (in.read(buffer, sizeof buffer) || in.gcount() > 0) f->add(buffer, static_cast<std::size_t>(in.gcount()));
}

// The contents of a file, or of the regular files under a directory (their
// relative names and contents, in name order).
void add_contents(Fnv* f, const std::string& path) {
  namespace fs = std::filesystem;
  std::error_code ec;
  if (!fs::is_directory(path, ec)) {
    add_file(f, path);
    return;
  }
  std::vector<fs::path> files;
  for (const auto& entry : fs::recursive_directory_iterator(path, ec)) {
    if (entry.is_regular_file(ec)) files.push_back(entry.path());
  }
  std::sort(files.begin(), files.end());
  for (const fs::path& file : files) {
    f->add(fs::relative(file, path, ec).generic_string());
    add_file(f, file);
  }
}

}  // namespace

std::vector<std::pair<std::string, std::uint64_t>> option_fingerprints(const CLI::App& command) {
  std::map<std::string, PathRole> roles;
  for (const RolePath& p : given_paths(command.get_name())) roles[p.option] = p.role;
  std::vector<std::pair<std::string, std::uint64_t>> out;
  for (const CLI::Option* option : command.get_options()) {
    std::string name = option->get_name(false, true);
    if (name == "--help") continue;
    std::string shown = name;
    if (option->get_positional()) {
      for (char& c : shown) c = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
    }
    Fnv f;
    const auto role = roles.find(shown);
    if (role != roles.end() && role->second != PathRole::Input && role->second != PathRole::Scene) {
      // An output: rank 0 writes it, the others' paths do not matter.
    } else if (role != roles.end()) {
      shown = "the contents of " + shown;
      // Every file the path stands for: a TetGen set, the files a scene names.
      for (const std::string& value : option->results()) {
        std::vector<RolePath> files;
        try {
          files = files_of({shown, value, role->second});
        } catch (const std::exception&) {
          files = {{shown, value, role->second}};  // not JSON: its contents say so, on every rank alike
        }
        for (const RolePath& file : files) add_contents(&f, file.path);
      }
    } else {
      f.add(std::to_string(option->count()));
      for (const std::string& value : option->results()) f.add(value);
    }
    out.emplace_back(std::move(shown), f.h);
  }
  return out;
}

std::string rank_mismatch(const std::vector<std::string>& names,
                          const std::vector<std::vector<std::uint64_t>>& fingerprints) {
  std::vector<std::string> differences;
  for (std::size_t i = 0; i < names.size(); ++i) {
    std::vector<std::size_t> ranks;
    for (std::size_t r = 1; r < fingerprints.size(); ++r) {
      if (fingerprints[r].size() != names.size() || fingerprints[r][i] != fingerprints[0][i]) ranks.push_back(r);
    }
    if (ranks.empty()) continue;
    const bool plural_name = names[i].rfind("the contents of ", 0) == 0;
    differences.push_back(fmt::format("{} {} on rank{} {}", names[i], plural_name ? "differ" : "differs",
                                      ranks.size() > 1 ? "s" : "", fmt::join(ranks, ", ")));
  }
  if (differences.empty()) return "";
  return fmt::format(
      "the ranks were not given the same inputs: {} (from rank 0's); every rank must run the same command on the "
      "same files",
      fmt::join(differences, "; "));
}

}  // namespace qpr
