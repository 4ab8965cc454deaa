// Argument conversion and checks for the bindings (the Python side of the
// API-boundary error layer, common.h). Vectors on the per-call path (solve,
// solve_in_D, reconstruct, out=) are used in place: they must already be
// contiguous 1-D NumPy arrays of the solver's dtype. Matrices given to
// precompute-type calls are copied anyway, so qpreduce/_convert.py accepts
// any real dtype and layout, scipy.sparse or dense, and names the argument
// and the expected shape when it refuses.
#pragma once

#include <qpreduce/common.h>

#include <pybind11/eigen.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <initializer_list>
#include <string>

namespace qpreduce::python {

namespace py = pybind11;

// An expected dimension: its size (−1: any) and its name in the docs ("n").
struct Dim {
  Index size = -1;
  const char* label = "";
};

// "(n,) = (12,)" or "(n, d) = (12, 4)" ("any" for a dimension of size −1).
std::string shape_text(Dim rows);
std::string shape_text(Dim rows, Dim cols);

// A compressed-column copy of a scipy.sparse matrix or 2-D array (any real
// dtype and index dtype), through qpreduce._convert.as_csc.
template <typename Scalar>
SparseMatrix<Scalar> sparse_arg(const char* name, py::handle value, Dim rows, Dim cols);
// A square n × n sparse copy (sparse_arg with a check that rows = cols).
template <typename Scalar>
SparseMatrix<Scalar> square_sparse_arg(const char* name, py::handle value);

// The design of a precompute: H (n×n), C (n×d) and D (n×k; None gives k = 0).
template <typename Scalar>
struct DesignArgs {
  SparseMatrix<Scalar> H, C, D;
};
template <typename Scalar>
DesignArgs<Scalar> design_args(py::handle H, py::handle C, py::handle D);

// A dense copy of a 2-D array or scipy.sparse matrix (qpreduce._convert.as_dense).
template <typename Scalar>
Matrix<Scalar> dense_arg(const char* name, py::handle value, Dim rows, Dim cols);
// A copy of a 1-D array-like of real numbers (qpreduce._convert.as_vector).
template <typename Scalar>
Vector<Scalar> vector_copy_arg(const char* name, py::handle value, Dim size);

// A 1-D array used in place; TypeError unless `value` is a numpy.ndarray of
// Scalar, ValueError on a wrong shape, non-contiguous strides or (inputs)
// NaN/Inf entries. `writable` for out= arguments.
template <typename Scalar>
Eigen::Map<Vector<Scalar>> vector_view(const char* name, py::handle value, Dim size, bool writable);

// Reads `value` (an input vector) in place.
template <typename Scalar>
Eigen::Map<const Vector<Scalar>> vector_arg(const char* name, py::handle value, Dim size) {
  const auto view = vector_view<Scalar>(name, value, size, false);
  return Eigen::Map<const Vector<Scalar>>(view.data(), view.size());
}

// A C-contiguous 2-D array used in place (rows × cols, row-major), with the
// checks of vector_view; e.g. the n × 3 vertices a deformer frame writes.
template <typename Scalar>
using RowMap = Eigen::Map<Eigen::Matrix<Scalar, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>>;
template <typename Scalar>
RowMap<Scalar> matrix_view(const char* name, py::handle value, Dim rows, Dim cols, bool writable);

// An input vector read in place (vector_arg: contiguous), by its name.
template <typename Scalar>
struct InputSpan {
  const char* name;
  const Eigen::Map<const Vector<Scalar>>& values;
};

// `out` when given (checked as vector_view), else a new array of `size`.
// ValueError when `out` shares memory with any of `inputs` ("out: shares
// memory with b"): the call reads them while it writes out.
template <typename Scalar>
py::array_t<Scalar> output_arg(const char* name, py::handle out, Dim size,
                               std::initializer_list<InputSpan<Scalar>> inputs = {});

// Raises qpreduce.NumericalError(status, message) with .summary = `summary_object`
// (the Python view of `summary`) unless summary.usable().
void raise_if_unusable(const Outcome& summary, py::handle summary_object);

// A result whose meaning changed (handles met only in the least-squares
// sense, a solve stopped at its round limit): warns with
// qpreduce.QpreduceWarning through Python's warnings, or under `strict`
// raises qpreduce.NumericalError(summary.status, message) with .summary.
// A warnings filter that turns the warning into an error raises it.
void warn_or_raise(const std::string& message, bool strict, const Outcome& summary, py::handle summary_object);

// Options argument: the default T{} for None, else a T (TypeError otherwise).
template <typename T>
T options_arg(const char* name, py::handle value) {
  if (value.is_none()) return T{};
  if (!py::isinstance<T>(value)) {
    throw py::type_error(std::string(name) + ": expected " +
                         py::str(py::type::of<T>().attr("__name__")).cast<std::string>() + " or None, got " +
                         py::str(py::type::of(value).attr("__name__")).cast<std::string>());
  }
  return value.cast<T>();
}

}  // namespace qpreduce::python
