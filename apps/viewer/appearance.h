// qpr viewer — how both modes (headless and the window) draw a session:
// vertex colours of the categorical modes, handle markers, camera framing.
#pragma once

#include "camera.h"
#include "renderer.h"
#include "session.h"
#include "viewer.h"

#include <vector>

namespace qpr::viewer {

// Per-vertex colours of a categorical mode (the deviation mode is coloured in
// the shader): rotational clusters, linear proxies (groups, or the nearest
// sample), affine patches; grey elsewhere. n entries.
std::vector<Eigen::Vector3f> vertex_colors(ColorMode mode, const Session& session);

// The vertices of every handle of the session, for the handle markers.
std::vector<unsigned> handle_markers(const Session& session);

// Frames the rest pose V (n × 3) and, when given, the deformed one, from the
// options' up axis, direction and zoom.
void set_camera(Camera* camera, const qpreduce::deform::Vertices& V, const ViewerOptions& o,
                const qpreduce::deform::Vertices* deformed = nullptr);

}  // namespace qpr::viewer
