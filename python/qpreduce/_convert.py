"""Argument conversion for the compiled module (called from C++).

Matrices handed to precompute-type calls are copied anyway, so these accept
scipy.sparse matrices (CSC, CSR, COO, ... with any index dtype) and NumPy
arrays of any real dtype and layout, and raise TypeError/ValueError naming
the argument and the expected shape otherwise. A sparse matrix is checked
(checked_sparse) before any SciPy conversion reads it. Each ``dim`` is a pair
(size, label) with size -1 for "any".
"""

from types import SimpleNamespace

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


class _Malformed(ValueError):
    """A sparse matrix whose arrays do not describe a matrix of its shape."""


def _index_array(what, array):
    """array (an index array of a sparse matrix) as a 1-D integer ndarray."""
    array = np.asarray(array)
    if array.dtype.kind not in "iu":
        raise TypeError(f"{what} must hold integers, got dtype {array.dtype}")
    if array.ndim != 1:
        raise _Malformed(f"{what} must be 1-D, got shape {array.shape}")
    return array


def _check_range(what, array, size, size_name):
    if array.size and (array.min() < 0 or array.max() >= size):
        raise _Malformed(f"{what} must lie in [0, {size}) ({size_name}), got values in [{array.min()}, {array.max()}]")


def _compressed(value, kind):
    """A new CSR, CSC or BSR matrix over value's arrays, after checking what
    SciPy's C++ conversions assume (SciPy's own check_format would prune and
    cast the caller's matrix in place)."""
    rows, cols = value.shape
    data = np.asarray(value.data)
    block = data.shape[1:] if kind == "bsr" else (1, 1)
    if len(block) != 2 or min(block) < 1:
        raise _Malformed(f"data must have shape (blocks, R, C), got {data.shape}")
    if rows % block[0] or cols % block[1]:
        raise _Malformed(f"the shape is not a multiple of the block size {block}")
    major, minor = (cols, rows) if kind == "csc" else (rows // block[0], cols // block[1])
    minor_name = {"csc": "the row count", "csr": "the column count", "bsr": "the block column count"}[kind]
    indptr = _index_array("indptr", value.indptr)
    indices = _index_array("indices", value.indices)
    if len(indptr) != major + 1:
        raise _Malformed(f"indptr must have {major + 1} entries, got {len(indptr)}")
    if indptr[0] != 0:
        raise _Malformed(f"indptr must start at 0, got {indptr[0]}")
    if np.any(np.diff(indptr) < 0):
        raise _Malformed("indptr must be non-decreasing")
    nnz = int(indptr[-1])
    if len(indices) < nnz:
        raise _Malformed(f"indptr ends at {nnz} but indices has {len(indices)} entries")
    expected = (len(indices),) + (tuple(block) if kind == "bsr" else ())
    if data.shape != expected:
        raise _Malformed(f"data must have shape {expected} (an entry per index), got {data.shape}")
    _check_range("indices", indices[:nnz], minor, minor_name)
    parts = (data[:nnz], indices[:nnz], indptr)
    if kind == "bsr":
        return scipy.sparse.bsr_matrix(parts, shape=value.shape, blocksize=tuple(block))
    return (scipy.sparse.csc_matrix if kind == "csc" else scipy.sparse.csr_matrix)(parts, shape=value.shape)


def _coo(value):
    """A new COO matrix from value's row, col and data (any object with them)."""
    row = _index_array("row", value.row)
    col = _index_array("col", value.col)
    data = np.asarray(value.data)
    if data.ndim != 1 or not len(row) == len(col) == len(data):
        raise _Malformed(f"row, col and data must be 1-D of one length, got shapes {row.shape}, {col.shape} and "
                         f"{data.shape}")
    _check_range("row", row, value.shape[0], "the row count")
    _check_range("col", col, value.shape[1], "the column count")
    return scipy.sparse.coo_matrix((data, (row, col)), shape=value.shape)


def _lil_triplets(value):
    """The triplets of a LIL matrix, read without SciPy's Cython flattening
    (which trusts the lengths of the row lists)."""
    rows, data = value.rows, value.data
    if len(rows) != value.shape[0] or len(data) != value.shape[0]:
        raise _Malformed(f"{value.shape[0]} row lists expected, got {len(rows)} index and {len(data)} value lists")
    lengths = [len(r) for r in rows]
    if any(len(d) != k for d, k in zip(data, lengths)):
        raise _Malformed("a row has more or fewer values than column indices")
    col = np.array([c for r in rows for c in r])
    return SimpleNamespace(row=np.repeat(np.arange(len(rows)), lengths), col=col if col.size else col.astype(int),
                           data=np.array([x for d in data for x in d], dtype=value.dtype), shape=value.shape)


def checked_sparse(name, value):
    """A new scipy.sparse matrix with value's entries, every index array and
    length checked first, so that SciPy's unchecked C++ conversions (tocsc,
    toarray) cannot read or write out of bounds: a matrix whose arrays were
    changed after construction raises ValueError (TypeError for non-integer
    indices) naming the argument. value itself is not changed. Duplicate
    entries stay (the conversions sum them, as SciPy does)."""
    kind = getattr(value, "format", None)
    try:
        if kind in ("csr", "csc", "bsr"):
            return _compressed(value, kind)
        if kind == "lil":
            return _coo(_lil_triplets(value))
        if kind == "coo":
            return _coo(value)
        if kind in ("dia", "dok"):  # their tocoo is NumPy code; the triplets are checked next
            try:
                coo = value.tocoo()
            except (ValueError, IndexError, TypeError, OverflowError) as error:
                raise _Malformed(str(error)) from None
            return _coo(coo)
        raise TypeError(f"{name}: unsupported scipy.sparse format {kind!r}")
    except _Malformed as error:
        raise ValueError(f"{name}: not a valid {str(kind).upper()} matrix of shape {value.shape}: {error}") from None
    except TypeError as error:
        if str(error).startswith(f"{name}:"):
            raise
        raise TypeError(f"{name}: not a valid {str(kind).upper()} matrix: {error}") from None


def as_csc(name, value, rows, cols, dtype):
    """Canonical CSC copy (sorted, no duplicates, int32 indices) of value."""
    if scipy.sparse.issparse(value):
        _check_kind(name, value.dtype, "a sparse matrix")
        _check_shape(name, value.shape, (rows, cols))
        value = checked_sparse(name, value)
        if max(value.shape) > _INT32_MAX or value.nnz > _INT32_MAX:
            raise ValueError(f"{name}: too large for 32-bit indices ({value.shape}, {value.nnz} entries)")
        matrix = value.tocsc()
    elif isinstance(value, np.ndarray):
        _check_kind(name, value.dtype, "an array")
        _check_shape(name, value.shape, (rows, cols))
        matrix = scipy.sparse.csc_matrix(value)
    else:
        raise TypeError(f"{name}: expected a scipy.sparse matrix or numpy.ndarray of shape "
                        f"{_shape_text((rows, cols))}, got {type(value).__name__}")
    if matrix.nnz > _INT32_MAX or max(matrix.shape) > _INT32_MAX:
        raise ValueError(f"{name}: too large for 32-bit indices ({matrix.shape}, {matrix.nnz} nonzeros)")
    # A new matrix over the arrays: no sorted/canonical flags cached from before.
    matrix = scipy.sparse.csc_matrix((matrix.data.astype(dtype), matrix.indices.astype(np.int32),
                                      matrix.indptr.astype(np.int32)), shape=matrix.shape)
    matrix.sum_duplicates()  # also sorts the row indices of each column
    return matrix


def as_dense(name, value, rows, cols, dtype):
    """Dense Fortran-ordered copy of a 2-D array or sparse matrix."""
    if scipy.sparse.issparse(value):
        _check_kind(name, value.dtype, "a sparse matrix")
        _check_shape(name, value.shape, (rows, cols))
        value = checked_sparse(name, value).toarray()
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
        raise TypeError(f"{name}: expected integers with shape {_shape_text(((size, label),))}, got dtype "
                        f"{array.dtype}")
    _check_shape(name, array.shape, ((size, label),))
    if array.size and (array.min() < -_INT32_MAX or array.max() > _INT32_MAX):
        raise ValueError(f"{name}: entries out of the 32-bit range")
    return np.ascontiguousarray(array, dtype=np.int32)
