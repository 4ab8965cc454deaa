#include "viewer.h"

#include "modes.h"

#include <fmt/format.h>

#include <stdexcept>

namespace qpr::viewer {

int run_viewer(ViewerInput input, const ViewerOptions& options, const SaveMeshFn& save_mesh) {
  if (options.width < 16 || options.height < 16 || options.width > 8192 || options.height > 8192)
    throw std::invalid_argument(fmt::format("image size {}×{} outside [16, 8192]", options.width, options.height));
  if (input.faces.rows() == 0) throw std::invalid_argument("the mesh has no triangle to draw");
  Session session(std::move(input));
  if (!options.screenshot.empty()) return run_headless(session, options, save_mesh);
  return run_interactive(session, options, save_mesh);
}

}  // namespace qpr::viewer
