#include "arguments.h"

#include <cmath>

namespace qpreduce::python {

namespace {

std::string dim_text(Dim dim, bool value) {
  if (!value) return dim.label;
  return dim.size < 0 ? std::string("any") : std::to_string(dim.size);
}

py::object convert(const char* function) { return py::module_::import("qpreduce._convert").attr(function); }

py::tuple dim_tuple(Dim dim) { return py::make_tuple(dim.size, dim.label); }

template <typename Scalar>
py::object dtype_name() {
  return py::dtype::of<Scalar>().attr("name");
}

}  // namespace

std::string shape_text(Dim rows) { return "(" + dim_text(rows, false) + ",) = (" + dim_text(rows, true) + ",)"; }

std::string shape_text(Dim rows, Dim cols) {
  return "(" + dim_text(rows, false) + ", " + dim_text(cols, false) + ") = (" + dim_text(rows, true) + ", " +
         dim_text(cols, true) + ")";
}

template <typename Scalar>
SparseMatrix<Scalar> sparse_arg(const char* name, py::handle value, Dim rows, Dim cols) {
  return convert("as_csc")(name, value, dim_tuple(rows), dim_tuple(cols), dtype_name<Scalar>())
      .template cast<SparseMatrix<Scalar>>();
}

template <typename Scalar>
SparseMatrix<Scalar> square_sparse_arg(const char* name, py::handle value) {
  auto H = sparse_arg<Scalar>(name, value, {-1, "n"}, {-1, "n"});
  if (H.rows() != H.cols()) {
    throw py::value_error(std::string(name) + ": expected a square matrix of shape (n, n), got (" +
                          std::to_string(H.rows()) + ", " + std::to_string(H.cols()) + ")");
  }
  return H;
}

template <typename Scalar>
DesignArgs<Scalar> design_args(py::handle H, py::handle C, py::handle D) {
  DesignArgs<Scalar> design;
  design.H = square_sparse_arg<Scalar>("H", H);
  const Index n = design.H.rows();
  design.C = sparse_arg<Scalar>("C", C, {n, "n"}, {-1, "d"});
  design.D = D.is_none() ? SparseMatrix<Scalar>(n, 0) : sparse_arg<Scalar>("D", D, {n, "n"}, {-1, "k"});
  return design;
}

template <typename Scalar>
Matrix<Scalar> dense_arg(const char* name, py::handle value, Dim rows, Dim cols) {
  return convert("as_dense")(name, value, dim_tuple(rows), dim_tuple(cols), dtype_name<Scalar>())
      .template cast<Matrix<Scalar>>();
}

template <typename Scalar>
Vector<Scalar> vector_copy_arg(const char* name, py::handle value, Dim size) {
  return convert("as_vector")(name, value, dim_tuple(size), dtype_name<Scalar>()).template cast<Vector<Scalar>>();
}

namespace {

// The array behind `value` when it is a numpy.ndarray of Scalar; TypeError
// with expected() and what it got otherwise.
template <typename Scalar, typename Expected>
py::array typed_array(py::handle value, const Expected& expected) {
  if (!py::isinstance<py::array>(value)) {
    throw py::type_error(expected() + ", got " + py::str(py::type::of(value).attr("__name__")).cast<std::string>());
  }
  auto array = py::reinterpret_borrow<py::array>(value);
  if (!array.dtype().is(py::dtype::of<Scalar>()) && !array.dtype().equal(py::dtype::of<Scalar>())) {
    throw py::type_error(expected() + ", got dtype " + py::str(value.attr("dtype")).cast<std::string>());
  }
  return array;
}

// ValueError when `array` is an out= argument (writable) that is read-only,
// or an input whose entries (`map`) are not all finite.
template <typename Map>
void check_entries(const char* name, const py::array& array, const Map& map, bool writable) {
  if (writable && !array.writeable()) {
    throw py::value_error(std::string(name) + ": the array is read-only");
  }
  if (!writable && !map.allFinite()) {
    throw py::value_error(std::string(name) + ": contains NaN or infinite entries");
  }
}

void throw_not_contiguous(const char* name, py::handle value, const char* what) {
  throw py::value_error(std::string(name) + ": expected " + what + " array, got strides " +
                        py::str(value.attr("strides")).cast<std::string>() + " (use numpy.ascontiguousarray)");
}

}  // namespace

template <typename Scalar>
Eigen::Map<Vector<Scalar>> vector_view(const char* name, py::handle value, Dim size, bool writable) {
  // On the per-call path: the messages are built only when a check fails.
  const auto expected = [&] {
    return std::string(name) + ": expected a numpy.ndarray of " + dtype_name<Scalar>().template cast<std::string>() +
           " with shape " + shape_text(size);
  };
  const py::array array = typed_array<Scalar>(value, expected);
  if (array.ndim() != 1 || array.shape(0) != size.size) {
    throw py::value_error(expected() + ", got " + py::str(value.attr("shape")).cast<std::string>());
  }
  if (size.size > 1 && array.strides(0) != static_cast<py::ssize_t>(sizeof(Scalar))) {
    throw_not_contiguous(name, value, "a contiguous");
  }
  Eigen::Map<Vector<Scalar>> map(static_cast<Scalar*>(const_cast<void*>(array.data())), size.size);
  check_entries(name, array, map, writable);
  return map;
}

template <typename Scalar>
RowMap<Scalar> matrix_view(const char* name, py::handle value, Dim rows, Dim cols, bool writable) {
  const auto expected = [&] {
    return std::string(name) + ": expected a numpy.ndarray of " + dtype_name<Scalar>().template cast<std::string>() +
           " with shape " + shape_text(rows, cols);
  };
  const py::array array = typed_array<Scalar>(value, expected);
  if (array.ndim() != 2 || (rows.size >= 0 && array.shape(0) != rows.size) ||
      (cols.size >= 0 && array.shape(1) != cols.size)) {
    throw py::value_error(expected() + ", got " + py::str(value.attr("shape")).cast<std::string>());
  }
  if (!(array.flags() & py::array::c_style)) throw_not_contiguous(name, value, "a C-contiguous");
  RowMap<Scalar> map(static_cast<Scalar*>(const_cast<void*>(array.data())), array.shape(0), array.shape(1));
  check_entries(name, array, map, writable);
  return map;
}

template <typename Scalar>
py::array_t<Scalar> output_arg(const char* name, py::handle out, Dim size,
                               std::initializer_list<InputSpan<Scalar>> inputs) {
  if (out.is_none()) return py::array_t<Scalar>(size.size);
  const auto o = vector_view<Scalar>(name, out, size, true);
  // Both contiguous (vector_view): they overlap when their ranges do.
  for (const InputSpan<Scalar>& in : inputs) {
    const Scalar* begin = in.values.data();
    if (o.size() > 0 && in.values.size() > 0 && o.data() < begin + in.values.size() && begin < o.data() + o.size()) {
      throw py::value_error(std::string(name) + ": shares memory with " + in.name +
                            ", which the call reads while it writes " + name + " (pass another array, or None)");
    }
  }
  return py::reinterpret_borrow<py::array_t<Scalar>>(out);
}

namespace {
// Raises qpreduce.NumericalError(status, message) with .summary.
[[noreturn]] void raise_numerical_error(Status status, const std::string& message, py::handle summary_object) {
  py::object error = py::module_::import("qpreduce").attr("NumericalError")(status, message);
  error.attr("summary") = summary_object;
  PyErr_SetObject(reinterpret_cast<PyObject*>(Py_TYPE(error.ptr())), error.ptr());
  throw py::error_already_set();
}
}  // namespace

void raise_if_unusable(const Outcome& summary, py::handle summary_object) {
  if (!summary.usable()) raise_numerical_error(summary.status, summary.message, summary_object);
}

void warn_or_raise(const std::string& message, bool strict, const Outcome& summary, py::handle summary_object) {
  if (strict) raise_numerical_error(summary.status, message, summary_object);
  const py::object category = py::module_::import("qpreduce").attr("QpreduceWarning");
  if (PyErr_WarnEx(category.ptr(), message.c_str(), 1) != 0) throw py::error_already_set();
}

#define QPREDUCE_PYTHON_ARGUMENTS(Scalar)                                                          \
  template SparseMatrix<Scalar> sparse_arg<Scalar>(const char*, py::handle, Dim, Dim);             \
  template SparseMatrix<Scalar> square_sparse_arg<Scalar>(const char*, py::handle);                 \
  template DesignArgs<Scalar> design_args<Scalar>(py::handle, py::handle, py::handle);              \
  template Matrix<Scalar> dense_arg<Scalar>(const char*, py::handle, Dim, Dim);                    \
  template Vector<Scalar> vector_copy_arg<Scalar>(const char*, py::handle, Dim);                   \
  template Eigen::Map<Vector<Scalar>> vector_view<Scalar>(const char*, py::handle, Dim, bool);     \
  template RowMap<Scalar> matrix_view<Scalar>(const char*, py::handle, Dim, Dim, bool);            \
  template py::array_t<Scalar> output_arg<Scalar>(const char*, py::handle, Dim,                            \
                                                  std::initializer_list<InputSpan<Scalar>>);
QPREDUCE_PYTHON_ARGUMENTS(double)
QPREDUCE_PYTHON_ARGUMENTS(float)
#undef QPREDUCE_PYTHON_ARGUMENTS

}  // namespace qpreduce::python
