// Internal: the checks of a DeformableMesh and of a handle set, shared by the
// deformer (precompute, set_handles) and the full-space references
// (reference/reference.cpp), so both refuse the same inputs with the same
// messages.
#pragma once

#include "qpreduce/deform/deformer/handles.h"

#include <vector>

namespace qpreduce::deform::detail {

// Throws std::invalid_argument unless exactly one of mesh.F and mesh.T is set
// and that mesh is valid (check_mesh). Messages start with `who`.
void check_mesh_elements(const DeformableMesh& mesh, const char* who);

// Throws std::invalid_argument unless mesh.patch_of_vertex is empty or has
// n = mesh.V.rows() entries in [-1, mesh.patch_types.size()). Messages start
// with `who`.
void check_patch_labels(const DeformableMesh& mesh, const char* who);

// Throws std::invalid_argument on a point handle without vertices, with
// weights missing (a group), mismatched or not finite, or with a vertex
// outside [0, n); on a prescribed patch outside [0, patch_types.size()),
// Fixed, or listed twice.
void check_handles(const Handles& handles, Index n, const std::vector<PatchType>& patch_types);

}  // namespace qpreduce::deform::detail
