// qpreduce::deform — procedural meshes for the demo, tests and benchmarks
// (no files needed). All are closed/consistently oriented as mesh.h describes.
#pragma once

#include "qpreduce/deform/mesh/mesh.h"

namespace qpreduce::deform::shapes {

// Closed capped cylinder around the z axis, z ∈ [0, height]: `rings` rings of
// `around` vertices (rings ≥ 2, around ≥ 3) plus one centre vertex per cap,
// outward-facing counter-clockwise triangles. Vertex v of ring j is
// j·around + v; the caps' centres are the last two vertices (bottom, top).
// Throws std::invalid_argument on sizes out of range, or more than 2³¹ − 1
// vertices or triangles (the meshes' indices are int).
TriangleMesh capped_cylinder(double radius, double height, Index around, Index rings);

// Axis-aligned box [0, sx] × [0, sy] × [0, sz] split into nx × ny × nz cubes of
// six positively oriented tets each (Freudenthal split along the main diagonal),
// with its boundary triangles. Vertex (i, j, k) is i + (nx+1)·(j + (ny+1)·k).
// Throws std::invalid_argument on sizes out of range, or more than 2³¹ − 1
// vertices or tets.
TetMesh box_tets(double sx, double sy, double sz, Index nx, Index ny, Index nz);

}  // namespace qpreduce::deform::shapes
