#include "bindings.h"

PYBIND11_MODULE(_qpreduce, m) {
  m.doc() = "qpreduce's compiled core; use it through the package `qpreduce`.";
  qpreduce::python::bind_options(m);
  qpreduce::python::bind_solver(m);
  qpreduce::python::bind_analysis(m);
  qpreduce::python::bind_problems(m);
  qpreduce::python::bind_deform_io(m);
}
