// qpr app support — no output may be an input.
//
// Each command names the options that hold paths and what it does with them:
// reads (Input), reads with the files it names (Scene: a JSON scene), writes
// (Output), writes a directory's files (OutputDirectory), or reads when it
// can and writes otherwise (Cache). A TetGen path (.node, .ele, .face) stands
// for its whole set. Before any work,
// check_path_roles resolves them (symbolic and hard links: the same device
// and inode) and refuses, naming both options, an output that is an input or
// another output, and a cache that names an existing file which is not a
// qpreduce cache (docs/robustness.md, "No output may be an input").
#pragma once

#include <string>
#include <vector>

#include <CLI/CLI.hpp>

namespace qpr {

enum class PathRole { Input, Scene, Output, OutputDirectory, Cache };

// One path a command reads or writes: the option that gave it ("--out",
// "MESH"), the path, and the role.
struct RolePath {
  std::string option;
  std::string path;
  PathRole role = PathRole::Input;
};

// The files `given` stands for, each named for messages: itself; for a
// TetGen path its .node, .ele and .face ("--out (its .ele)"); for a Scene
// also every file the scene names, as Inputs ("--scene's /mesh";
// qpreduce::deform::scene_files), with their TetGen sets. Throws
// qpreduce::deform::IoError when a scene cannot be read or is not JSON.
std::vector<RolePath> files_of(const RolePath& given);

// Registers `option` (a path option of the subcommand `command`) with `role`,
// for check_path_roles(command). Returns option.
CLI::Option* path_role(CLI::App* command, CLI::Option* option, PathRole role);

// Throws std::invalid_argument naming both options when an output (or cache)
// is the same file as an input (or a file a scene names) or as another
// output (files_of); a directory output clashes with a file input or output
// of the same path. Paths that are
// empty, or name an existing non-regular file (/dev/null, a FIFO), are not
// compared. A Cache path naming an existing non-empty file that does not
// start with a qpreduce cache's header is refused ("is not a qpreduce cache").
void check_path_roles(const std::vector<RolePath>& paths);

// cmd->add_option(name, variable, description) registered with `role`.
template <typename T>
CLI::Option* add_path_option(CLI::App* cmd, PathRole role, const std::string& name, T& variable,
                             const std::string& description) {
  return path_role(cmd, cmd->add_option(name, variable, description), role);
}

// The paths given on `command`'s command line for the options registered
// with path_role, each named as in messages ("MESH", "--sel").
std::vector<RolePath> given_paths(const std::string& command);

// check_path_roles over the options registered for `command` (path_role)
// that were given on its command line, plus `extra` (paths a command derives,
// such as a default report inside an output directory).
void check_path_roles(const std::string& command, const std::vector<RolePath>& extra = {});

}  // namespace qpr
