// qpr viewer — the two ways run_viewer runs a session: headless (every
// frame of the scenario or the recording, one PNG, statistics) and
// interactive (the window with its panels).
#pragma once

#include "session.h"
#include "viewer.h"

namespace qpr::viewer {

// Runs every frame, renders the last one to options.screenshot and prints
// (and with options.stats_json writes) the timings. Returns the exit code.
int run_headless(Session& session, const ViewerOptions& options, const SaveMeshFn& save_mesh);

// Opens the window and runs until it is closed (or options.max_frames).
int run_interactive(Session& session, const ViewerOptions& options, const SaveMeshFn& save_mesh);

}  // namespace qpr::viewer
