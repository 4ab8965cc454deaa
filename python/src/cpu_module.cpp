// qpreduce._cpu: the run-time kernel choices of qpreduce/util/cpu_features.h,
// in a module that links no BLAS, so that the package can prefer OpenBLAS's
// kernels for this CPU before NumPy or _qpreduce loads OpenBLAS.
#include <qpreduce/util/cpu_features.h>

#include <pybind11/pybind11.h>

PYBIND11_MODULE(_cpu, m) {
  m.doc() = "Which kernels the system BLAS runs (qpreduce/util/cpu_features.h).";
  m.def("preferred_blas_core", &qpreduce::preferred_blas_core,
        "The OpenBLAS kernel family that suits this CPU (OPENBLAS_CORETYPE's name), or '' to keep "
        "OpenBLAS's own detection.");
  m.def("prefer_blas_core", &qpreduce::prefer_blas_core,
        "Sets OPENBLAS_CORETYPE to preferred_blas_core() unless it or QPREDUCE_KEEP_BLAS_CORE is set; "
        "effective only before OpenBLAS is loaded. Returns whether it set the variable.");
  m.def("blas_core", &qpreduce::blas_core,
        "The kernel family the loaded OpenBLAS runs ('Haswell', 'SkylakeX', 'Prescott', …), or '' without OpenBLAS.");
}
