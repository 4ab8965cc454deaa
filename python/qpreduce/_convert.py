"""Argument conversion for the compiled module (called from C++).

Matrices handed to precompute-type calls are copied anyway, so these accept
scipy.sparse matrices (CSC, CSR, COO, ... with any index dtype) and NumPy
arrays of any real dtype and layout, and raise TypeError/ValueError naming
the argument and the expected shape otherwise. Each ``dim`` is a pair
(size, label) with size -1 for "any".
"""

import numpy as np
import scipy.sparse

_INT32_MAX = np.iinfo(np.int32).max


def _shape_text(dims):
    labels = ", ".join(label for _, label in dims)
    sizes = ", ".join("any" if size < 0 else str(size) for size, _ in dims)
    if len(dims) == 1:
        return f"({labels},) = ({sizes},)"
    return f"({labels}) = ({sizes})"


def _check_kind(name, dtype, what):
    if dtype.kind not in "fiu":
        raise TypeError(f"{name}: expected {what} of real numbers, got dtype {dtype}")


def _check_shape(name, shape, dims):
    if len(shape) != len(dims) or any(size >= 0 and got != size for got, (size, _) in zip(shape, dims)):
        raise ValueError(f"{name}: expected shape {_shape_text(dims)}, got {tuple(shape)}")


def _check_structure(name, value):
    """ValueError naming the argument when the arrays of a scipy.sparse matrix
    do not describe a matrix of its shape (indices or indptr edited after
    construction): SciPy's own conversions do not check them and would read
    out of bounds."""
    fmt = value.format
    try:
        if fmt in ("csr", "csc", "bsr"):
            value.check_format(full_check=True)
        elif fmt == "coo":
            rows, cols = value.shape
            row, col, data = np.asarray(value.row), np.asarray(value.col), np.asarray(value.data)
            if not (row.ndim == col.ndim == data.ndim == 1 and row.size == col.size == data.size):
                raise ValueError("row, col and data differ in length")
            if row.size and (row.min() < 0 or row.max() >= rows or col.min() < 0 or col.max() >= cols):
                raise ValueError("a row or column index lies outside the shape %s" % (value.shape,))
        elif fmt in ("dok", "lil", "dia"):
            pass  # kept consistent by their own methods, or checked by tocsc
        else:
            raise TypeError("%s: unsupported scipy.sparse format %r" % (name, fmt))
    except (ValueError, IndexError) as error:
        raise ValueError("%s: not a valid %s matrix of shape %s: %s" % (name, fmt.upper(), value.shape, error)) \
            from None


def as_csc(name, value, rows, cols, dtype):
    """Canonical CSC copy (sorted, no duplicates, int32 indices) of value."""
    if scipy.sparse.issparse(value):
        _check_kind(name, value.dtype, "a sparse matrix")
        _check_shape(name, value.shape, (rows, cols))
        _check_structure(name, value)
        matrix = scipy.sparse.csc_matrix(value, dtype=dtype, copy=True)
    elif isinstance(value, np.ndarray):
        _check_kind(name, value.dtype, "an array")
        _check_shape(name, value.shape, (rows, cols))
        matrix = scipy.sparse.csc_matrix(value.astype(dtype, copy=False))
    else:
        raise TypeError(f"{name}: expected a scipy.sparse matrix or numpy.ndarray of shape "
                        f"{_shape_text((rows, cols))}, got {type(value).__name__}")
    if matrix.nnz > _INT32_MAX or max(matrix.shape) > _INT32_MAX:
        raise ValueError(f"{name}: too large for 32-bit indices ({matrix.shape}, {matrix.nnz} nonzeros)")
    matrix.indices = matrix.indices.astype(np.int32, copy=False)
    matrix.indptr = matrix.indptr.astype(np.int32, copy=False)
    matrix.sum_duplicates()  # also sorts the row indices of each column
    return matrix


def as_dense(name, value, rows, cols, dtype):
    """Dense Fortran-ordered copy of a 2-D array or sparse matrix."""
    if scipy.sparse.issparse(value):
        _check_kind(name, value.dtype, "a sparse matrix")
        value = value.toarray()
    elif not isinstance(value, np.ndarray):
        raise TypeError(f"{name}: expected a numpy.ndarray or scipy.sparse matrix of shape "
                        f"{_shape_text((rows, cols))}, got {type(value).__name__}")
    _check_kind(name, value.dtype, "an array")
    _check_shape(name, value.shape, (rows, cols))
    return np.asfortranarray(value, dtype=dtype)


def as_vector(name, value, size, dtype):
    """Contiguous 1-D copy of an array-like of real numbers."""
    if scipy.sparse.issparse(value):
        raise TypeError(f"{name}: expected a 1-D array of shape {_shape_text((size,))}, got a sparse matrix")
    array = np.asarray(value)
    _check_kind(name, array.dtype, "an array")
    _check_shape(name, array.shape, (size,))
    return np.ascontiguousarray(array, dtype=dtype)


def as_rows(name, value, cols, label, dtype):
    """C-contiguous (rows, cols) copy of a NumPy array: vertices (dtype float64,
    any real input, finite) or elements (dtype int32, integer input only).
    ``cols`` is a tuple of the accepted column counts, ``label`` names the
    rows ("n", "m")."""
    target = np.dtype(dtype)
    shapes = " or ".join(f"({label}, {c})" for c in cols)
    if not isinstance(value, np.ndarray):
        raise TypeError(f"{name}: expected a numpy.ndarray of shape {shapes}, got {type(value).__name__}")
    if value.dtype.kind not in ("iu" if target.kind == "i" else "fiu"):
        what = "integers" if target.kind == "i" else "real numbers"
        raise TypeError(f"{name}: expected an array of {what} with shape {shapes}, got dtype {value.dtype}")
    if value.ndim != 2 or value.shape[1] not in cols:
        raise ValueError(f"{name}: expected shape {shapes}, got {value.shape}")
    if target.kind == "i":
        if value.size and (value.min() < 0 or value.max() > _INT32_MAX):
            raise ValueError(f"{name}: indices must lie in [0, 2^31), got [{value.min()}, {value.max()}]")
    elif not np.all(np.isfinite(value)):
        raise ValueError(f"{name}: contains NaN or infinite entries")
    return np.ascontiguousarray(value, dtype=target)


def as_labels(name, value, size, label):
    """1-D int32 copy of an integer array-like of length size (labels, indices)."""
    array = np.asarray(value)
    if array.size == 0:
        array = array.astype(np.int32)
    if array.dtype.kind not in "iu":
        raise TypeError(f"{name}: expected integers with shape ({label},) = ({size},), got dtype {array.dtype}")
    _check_shape(name, array.shape, ((size, label),))
    if array.size and (array.min() < -_INT32_MAX or array.max() > _INT32_MAX):
        raise ValueError(f"{name}: entries out of the 32-bit range")
    return np.ascontiguousarray(array, dtype=np.int32)
