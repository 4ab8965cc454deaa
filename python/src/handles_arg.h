// The handle sets users pass as sequences (bind_handles.cpp), for
// Deformer.set_handles and Refiner.refine.
#pragma once

#include <qpreduce/deform/deformer/handles.h>

#include <pybind11/pybind11.h>

namespace qpreduce::python {

namespace py = pybind11;

// A Handles object as is, or one made from a sequence whose items are vertex
// indices or (vertices, weights) pairs, plus `patches` (prescribed patch
// indices, or None). TypeError naming the item otherwise; the indices are
// checked where the handles are used (set_handles, handle_residual).
deform::Handles handles_arg(py::handle handles, py::handle patches);

}  // namespace qpreduce::python
