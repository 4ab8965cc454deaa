"""qpreduce: reduced quadratic programs through linear variational subspaces.

A thin layer over the C++ library (Ye & Yan, "On the Approximation Theory of
Linear Variational Subspace Design"). For

    min_X ½XᵀHX − qᵀX   s.t.  AᵀX = b     (H n×n sparse PSD, A n×m)

``SubspaceSolver.precompute(H, C, D)`` builds the subspace X = N·z + UD·y from
one factorization; ``set_constraints(A)`` and ``solve_in_D(b, Y)`` then answer
each demand in microseconds. See docs/python.md.

Bad arguments raise ValueError or TypeError naming the argument; numerical
outcomes come back as summaries with a ``status`` (``qpreduce.Status``), and
``summary.raise_if_failed()`` turns a failed one into ``NumericalError``.
"""

import sys as _sys

# Before anything loads OpenBLAS (NumPy, _qpreduce): prefer its kernels for
# this CPU where Debian's OpenBLAS would fall back to generic ones
# (qpreduce/util/cpu_features.h; a set OPENBLAS_CORETYPE is kept). When NumPy
# was imported first, OpenBLAS has chosen already: blas_core() says what runs.
from . import _cpu

if "numpy" not in _sys.modules:
    _cpu.prefer_blas_core()
blas_core = _cpu.blas_core

from . import _qpreduce  # noqa: E402
from ._qpreduce import (
    Backend,
    CompanionDemand,
    ConstraintOptions,
    ConstraintSummary,
    FactorSummary,
    FullSolveSummary,
    Outcome,
    PsdFactor,
    QuotientOptions,
    RoundStop,
    Status,
    SubspaceOptions,
    SubspaceSolver,
    SubspaceSolver32,
    SubspaceSummary,
    TheoremBound,
    TheoremCheck,
    TheoremChecker,
    TheoremSetupSummary,
    TheoremSolutions,
    TheoremStatus,
    WhitenedDesign,
    check_theorem,
    companion_demand,
    companion_solution,
    deform,
    factor_psd,
    families,
    generators,
    h_distance,
    solve_full,
    subspace_companion_solution,
    theorem_bound,
    whiten_design,
)

# `import qpreduce.families` and `from qpreduce.generators import ...` work too.
_sys.modules[__name__ + ".families"] = families
_sys.modules[__name__ + ".generators"] = generators
_sys.modules[__name__ + ".deform"] = deform
_sys.modules[__name__ + ".deform.shapes"] = deform.shapes


class QpreduceWarning(UserWarning):
    """A result whose meaning changed: handles met only in the least-squares
    sense, a solve stopped at its round limit. The message says how far off
    and what to do; ``strict=True`` (Deformer, ArapSolver, deform.arap) raises
    NumericalError instead, and ``warnings.simplefilter("error",
    QpreduceWarning)`` turns every one into an exception."""


class NumericalError(RuntimeError):
    """A numerical step failed: carries the step's ``status`` and ``message``."""

    def __init__(self, status, message):
        super().__init__(f"{status.name}: {message}" if message else status.name)
        self.status = status
        self.message = message


def _raise_if_failed(self, allow_qualified=True):
    """Raises NumericalError unless the step succeeded; returns self.

    allow_qualified: accept qualified answers (Status.ConstraintsLeastSquares),
    i.e. raise unless usable(); False raises unless ok().
    """
    if not (self.usable() if allow_qualified else self.ok()):
        raise NumericalError(self.status, self.message)
    return self


Outcome.raise_if_failed = _raise_if_failed

__all__ = [name for name in dir() if not name.startswith("_") and name != "annotations"]
