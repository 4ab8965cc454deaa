#include "qpreduce/deform/mesh/mesh.h"

#include <qpreduce/checks.h>

#include <fmt/format.h>

#include <stdexcept>

namespace qpreduce::deform {

namespace {
template <typename Elements>
void check_indices(const char* what, const char* elements, Index vertex_count, const Elements& E);
template <typename Elements>
void check_elements(const char* what, const char* elements, const Vertices& V, const Elements& E) {
  check_finite(what, V);
  if (V.rows() == 0) throw std::invalid_argument(fmt::format("{}: no vertices", what));
  if (E.rows() == 0) throw std::invalid_argument(fmt::format("{}: no {}", what, elements));
  check_indices(what, elements, V.rows(), E);
}
template <typename Elements>
void check_indices(const char* what, const char* elements, Index vertex_count, const Elements& E) {
  if (E.size() > 0 && (E.minCoeff() < 0 || E.maxCoeff() >= vertex_count)) {
    throw std::invalid_argument(fmt::format("{}: vertex index out of range in {}: expected [0, {}), got [{}, {}]",
                                            what, elements, vertex_count, E.minCoeff(), E.maxCoeff()));
  }
}
}  // namespace

void check_mesh(const char* what, const TriangleMesh& mesh) {
  check_elements(what, "triangles", mesh.V, mesh.F);
}

void check_mesh(const char* what, const TetMesh& mesh) {
  check_elements(what, "tetrahedra", mesh.V, mesh.T);
  check_indices(what, "boundary triangles", mesh.V.rows(), mesh.F);
}

}  // namespace qpreduce::deform
