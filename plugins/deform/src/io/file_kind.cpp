#include "qpreduce/deform/io/file_kind.h"

#include "format_common.h"

namespace qpreduce::deform {

std::string lower_case_extension(const std::string& path) { return detail::lower_extension(path); }

MeshFileKind mesh_file_kind(const std::string& path) {
  const std::string ext = detail::lower_extension(path);
  if (ext == ".obj" || ext == ".off" || ext == ".ply") return MeshFileKind::Surface;
  if (ext == ".mesh" || ext == ".node" || ext == ".ele") return MeshFileKind::Tets;
  return MeshFileKind::Unknown;
}

}  // namespace qpreduce::deform
