// The parts of the module _qpreduce, one function per header family.
#pragma once

#include <pybind11/pybind11.h>

namespace qpreduce::python {

namespace py = pybind11;

void bind_options(py::module_& m);   // common.h enums, options and summaries
void bind_solver(py::module_& m);    // subspace_solver.h
void bind_analysis(py::module_& m);  // full_solve.h, quotient.h, theorem.h
void bind_problems(py::module_& m);  // problems/families.h, problems/generators.h
// The submodule qpreduce.deform (made by bind_deform_io, which calls the ones below):
void bind_deform_io(py::module_& m);      // deform/io/*, mesh/shapes.h, reference/reference.h
void bind_deformer(py::module_& deform);  // deform/deformer/*: options, Model, Deformer
void bind_deformer_options(py::module_& deform);  // deformer.h: options and summaries (bind_deform_options.cpp)
void bind_handles(py::module_& deform);   // deform/deformer/handles.h: PointHandle, Handles, HandleTargets
void bind_refiner(py::module_& deform);   // deform/refine/refine.h: RefineOptions, Refiner
void bind_arap(py::module_& deform);      // deform/arap/arap.h: arap, ArapSolverOptions, ArapSolver
void bind_pipeline(py::module_& deform);  // deform/pipeline/run_scenario.h: run_scenario and its options

}  // namespace qpreduce::python
