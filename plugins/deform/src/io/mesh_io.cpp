// Extension dispatch for triangle meshes.
#include "format_common.h"

namespace qpreduce::deform {

TriangleMesh read_triangle_mesh(const std::string& path, MeshReadInfo* info) {
  const std::string ext = detail::lower_extension(path);
  if (ext == ".obj") return read_obj(path, info);
  if (ext == ".off") return read_off(path, info);
  if (ext == ".ply") return read_ply(path, info);
  detail::fail(path, 0, fmt::format("unsupported triangle mesh extension '{}' (expected .obj, .off or .ply)", ext));
}

void write_triangle_mesh(const std::string& path, const TriangleMesh& mesh) {
  const std::string ext = detail::lower_extension(path);
  if (ext == ".obj") return write_obj(path, mesh);
  if (ext == ".off") return write_off(path, mesh);
  if (ext == ".ply") return write_ply(path, mesh, PlyEncoding::Ascii);
  detail::fail(path, 0, fmt::format("unsupported triangle mesh extension '{}' (expected .obj, .off or .ply)", ext));
}

}  // namespace qpreduce::deform
