// The small meshes the energy and model tests share: a capped cylinder
// surface (spokes-and-rims elements) and a box of tets (tet elements).
#pragma once

#include "qpreduce/deform/energy/arap_energy.h"
#include "qpreduce/deform/mesh/shapes.h"

#include <vector>

namespace energy_test {

using qpreduce::Index;

// A mesh, its rotation elements and their clusters (labels in [0, d)).
struct ElementsCase {
  qpreduce::deform::Vertices V;
  qpreduce::deform::RotationElements el;
  std::vector<int> clusters;  // filled by the caller
  Index d = 0;
};

// The box of tets (1 × 1 × 2, 2 × 2 × 3 cells) when `tet`, else the capped
// cylinder (radius 1, height 3, 8 around, 6 rings); d clusters, unlabelled.
inline ElementsCase small_elements(bool tet, Index d) {
  namespace deform = qpreduce::deform;
  ElementsCase c;
  c.d = d;
  if (tet) {
    const deform::TetMesh m = deform::shapes::box_tets(1.0, 1.0, 2.0, 2, 2, 3);
    c.V = m.V;
    c.el = deform::tet_elements(m.V, m.T);
  } else {
    const deform::TriangleMesh m = deform::shapes::capped_cylinder(1.0, 3.0, 8, 6);
    c.V = m.V;
    c.el = deform::spokes_and_rims_elements(m.V, m.F);
  }
  return c;
}

}  // namespace energy_test
