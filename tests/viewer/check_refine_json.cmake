# cmake -DJSON=<file> -P check_refine_json.cmake
# Checks the stats of `qpr view --screenshot … --stats --refine`: the last
# frame's fixed-point residual and rounds, then the refine.* keys as for
# `qpr deform --refine` (tests/apps/check_refine_json.cmake: converged, energy
# not raised, arap_energy is the drawn refined pose's, distances ordered).
if(NOT EXISTS "${JSON}")
  message(FATAL_ERROR "no stats at ${JSON}")
endif()
file(READ "${JSON}" doc)
string(JSON fixed_point GET "${doc}" fixed_point_residual)
string(JSON frame_rounds GET "${doc}" rounds)
if(fixed_point LESS 0 OR frame_rounds LESS 1)
  message(FATAL_ERROR "fixed_point_residual ${fixed_point} after ${frame_rounds} rounds: expected ≥ 0 after ≥ 1")
endif()
include(${CMAKE_CURRENT_LIST_DIR}/../apps/check_refine_json.cmake)
