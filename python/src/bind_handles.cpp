// qpreduce.deform: the handle set of the on-site step and a frame's targets
// (deform/deformer/handles.h): PointHandle, Handles, HandleTargets, and the
// conversion of the sequences users pass instead (handles_arg.h).
#include "arguments.h"
#include "bindings.h"
#include "handles_arg.h"

#include <qpreduce/deform/deformer/handles.h>

#include <pybind11/eigen.h>
#include <pybind11/stl.h>

#include <string>
#include <vector>

namespace qpreduce::python {

using namespace qpreduce::deform;

namespace {

// A point handle from an int (one vertex), a pair (vertices, weights) or a
// PointHandle.
PointHandle point_handle_arg(py::handle item, size_t index) {
  if (py::isinstance<PointHandle>(item)) return item.cast<PointHandle>();
  PointHandle handle;
  const std::string name = "points[" + std::to_string(index) + "]";
  if (py::isinstance<py::int_>(item) || py::isinstance(item, py::module_::import("numpy").attr("integer"))) {
    try {
      handle.vertices = {item.cast<Index>()};
    } catch (const py::cast_error&) {  // beyond 64 bits: pybind11's RuntimeError would not name it
      throw py::value_error(name + ": vertex index " + py::str(item).cast<std::string>() + " is out of range");
    }
    return handle;
  }
  if (!py::isinstance<py::sequence>(item) || py::len(item) != 2) {
    throw py::type_error(name + ": expected a vertex index or a pair (vertices, weights), got " +
                         py::str(py::type::of(item).attr("__name__")).cast<std::string>());
  }
  const auto pair = py::reinterpret_borrow<py::sequence>(item);
  const auto convert = py::module_::import("qpreduce._convert");
  const auto vertices = convert.attr("as_labels")(name + " vertices", pair[0], -1, "g");
  const Index g = py::len(vertices);
  handle.vertices = vertices.cast<std::vector<Index>>();
  const auto weights = vector_copy_arg<double>((name + " weights").c_str(), pair[1], {g, "g"});
  handle.weights.assign(weights.data(), weights.data() + weights.size());
  return handle;
}

}  // namespace

void bind_handles(py::module_& m) {
  py::class_<PointHandle>(m, "PointHandle", "One vertex, or the weighted point Σ w_i v_i of a group.")
      .def(
          py::init([](std::vector<Index> vertices, std::vector<double> weights) {
            return PointHandle{std::move(vertices), std::move(weights)};
          }),
          py::arg("vertices"), py::arg("weights") = std::vector<double>{},
          "PointHandle(vertices, weights=[])\n\nvertices: g vertex indices; weights: g weights (the point Σ w_i v_i),\n"
          "or [] for a single vertex.")
      .def_readwrite("vertices", &PointHandle::vertices, "Vertex indices (g).")
      .def_readwrite("weights", &PointHandle::weights, "g weights, or [] for a single vertex.")
      .def("__repr__", [](const PointHandle& h) {
        return "PointHandle(vertices=" + py::repr(py::cast(h.vertices)).cast<std::string>() +
               ", weights=" + py::repr(py::cast(h.weights)).cast<std::string>() + ")";
      });
  py::class_<Handles>(m, "Handles",
                      "The handle set of the on-site step: point handles and prescribed patches.\n\n"
                      "Handles(points=[...], patches=[...]): each point an int (a vertex), a pair\n"
                      "(vertices, weights) or a PointHandle; patches are patch indices.")
      .def(
          py::init([](py::iterable points, std::vector<Index> patches) {
            Handles handles;
            size_t i = 0;
            for (py::handle item : points) handles.points.push_back(point_handle_arg(item, i++));
            handles.patches = std::move(patches);
            return handles;
          }),
          py::arg("points") = py::list(), py::arg("patches") = std::vector<Index>{},
          "Handles(points=[], patches=[])\n\npoints: h items, each a vertex index, a pair (vertices (g,), weights (g,))\n"
          "or a PointHandle; patches: s indices of the prescribed (non-fixed) patches.")
      .def_readwrite("points", &Handles::points, "List of PointHandle.")
      .def_readwrite("patches", &Handles::patches, "Prescribed patch indices.")
      .def("__repr__", [](const Handles& h) {
        return "Handles(" + std::to_string(h.points.size()) +
               " points, patches=" + py::repr(py::cast(h.patches)).cast<std::string>() + ")";
      });
  py::class_<HandleTargets>(m, "HandleTargets",
                            "Targets of one frame: points (h, 3), one per point handle, and one 3×4\n"
                            "[A | t] per prescribed patch (p ↦ A·p + t).")
      .def(py::init([](py::handle points, std::vector<Eigen::Matrix<double, 3, 4>> transforms) {
             HandleTargets t;
             t.points = dense_arg<double>("points", points, {-1, "h"}, {3, "3"});
             t.patch_transforms = std::move(transforms);
             return t;
           }),
           py::arg("points") = py::array_t<double>(std::vector<py::ssize_t>{0, 3}),
           py::arg("patch_transforms") = std::vector<Eigen::Matrix<double, 3, 4>>{},
           "HandleTargets(points=(0, 3) array, patch_transforms=[])\n\npoints: (h, 3), one row per point handle;\n"
           "patch_transforms: s arrays (3, 4) [A | t], one per prescribed patch. Copied.")
      .def_readwrite("points", &HandleTargets::points, "(h, 3)")
      .def_readwrite("patch_transforms", &HandleTargets::patch_transforms, "List of (3, 4) [A | t].");
}

Handles handles_arg(py::handle handles, py::handle patches) {
  if (py::isinstance<Handles>(handles)) {
    if (!patches.is_none()) throw py::type_error("patches: give them in the Handles object");
    return handles.cast<Handles>();
  }
  Handles h;
  if (!handles.is_none()) {
    if (!py::isinstance<py::iterable>(handles)) {
      throw py::type_error(
          "handles: expected a Handles, a sequence of vertex indices or (vertices, weights) pairs, or None, got " +
          py::str(py::type::of(handles).attr("__name__")).cast<std::string>());
    }
    size_t i = 0;
    for (py::handle item : handles) h.points.push_back(point_handle_arg(item, i++));
  }
  if (!patches.is_none()) {
    h.patches = py::module_::import("qpreduce._convert")
                    .attr("as_labels")("patches", patches, -1, "s")
                    .cast<std::vector<Index>>();
  }
  return h;
}

}  // namespace qpreduce::python
