// Helpers shared by the reference and refine tests: a small bent scenario
// (surface or tets) and distances between poses.
#pragma once

#include <catch2/catch.hpp>

#include "qpreduce/deform/io/scenario.h"
#include "qpreduce/deform/mesh/shapes.h"
#include "qpreduce/deform/reference/reference.h"

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <vector>

namespace qpreduce::deform::reference_test {

// A small mesh with its bottom layer Fixed and its top layer an Affine patch
// prescribed to rotate by `angle` about x and move sideways (a .sel/.def).
struct Case {
  DeformableMesh model;
  Handles handles;
  HandleTargets targets;
  ConstraintOptions constraints;  // for set_handles
};

inline Case bend_case(bool tet, double angle) {
  Case c;
  std::vector<int> roles;
  if (tet) {
    const TetMesh m = shapes::box_tets(1.0, 1.0, 2.0, 2, 2, 4);
    c.model.V = m.V;
    c.model.T = m.T;
  } else {
    const TriangleMesh m = shapes::capped_cylinder(1.0, 3.0, 8, 6);
    c.model.V = m.V;
    c.model.F = m.F;
  }
  const double zmax = c.model.V.col(2).maxCoeff();
  for (Index v = 0; v < c.model.V.rows(); ++v) {
    const double z = c.model.V(v, 2);
    roles.push_back(z < 1e-9 ? 0 : z > zmax - 1e-9 ? 2 : 1);
  }
  Eigen::Matrix4d def = Eigen::Matrix4d::Identity();
  def.topLeftCorner<3, 3>() = Eigen::AngleAxisd(angle, Eigen::Vector3d::UnitX()).toRotationMatrix();
  def.block<3, 1>(0, 3) = Eigen::Vector3d(0.3, -0.8, -0.4);
  const SelDefScenario sd = apply_sel_def(roles, def, &c.model);
  c.handles = sd.handles;
  c.targets = sd.targets;
  // Rotational clusters for E′: slabs along z.
  const Index r = tet ? c.model.T.rows() : c.model.V.rows();
  c.model.clusters.resize(static_cast<size_t>(r));
  for (Index k = 0; k < r; ++k) {
    double z = 0.0;
    if (tet) {
      for (int i = 0; i < 4; ++i) z += 0.25 * c.model.V(c.model.T(k, i), 2);
    } else {
      z = c.model.V(k, 2);
    }
    c.model.clusters[k] = std::min(3, static_cast<int>(4.0 * z / zmax));
  }
  return c;
}

inline double max_distance(const Vertices& A, const Vertices& B) { return (A - B).rowwise().norm().maxCoeff(); }
inline double rms_distance(const Vertices& A, const Vertices& B) {
  return std::sqrt((A - B).rowwise().squaredNorm().mean());
}

}  // namespace qpreduce::deform::reference_test
