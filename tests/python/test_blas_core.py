"""The BLAS kernels the package runs (qpreduce/util/cpu_features.h): imported
before NumPy, qpreduce prefers OpenBLAS's kernels for this CPU where Debian's
OpenBLAS would fall back to its generic Prescott ones; a choice the user made
(OPENBLAS_CORETYPE, QPREDUCE_KEEP_BLAS_CORE) is kept. Each case runs in a
fresh interpreter: OpenBLAS chooses once, when it loads."""

import os
import subprocess
import sys

import pytest


def _core(code, **env):
    environment = {k: v for k, v in os.environ.items() if k not in ("OPENBLAS_CORETYPE", "QPREDUCE_KEEP_BLAS_CORE")}
    environment.update(env)
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, env=environment)
    assert p.returncode == 0, p.stderr
    return p.stdout.strip()


def test_imported_first_qpreduce_runs_the_kernels_for_this_cpu():
    own = _core("import qpreduce, numpy; print(qpreduce.blas_core())", QPREDUCE_KEEP_BLAS_CORE="1")
    if not own:
        pytest.skip("the BLAS is not OpenBLAS")
    preferred = _core("from qpreduce import _cpu; print(_cpu.preferred_blas_core())")
    expected = preferred if own == "Prescott" and preferred else own
    assert _core("import qpreduce, numpy; print(qpreduce.blas_core())") == expected
    # NumPy first: OpenBLAS chose when NumPy loaded it, and qpreduce says so.
    assert _core("import numpy, qpreduce; print(qpreduce.blas_core())") == own
    # A core the user named is the one that runs.
    assert _core("import qpreduce; print(qpreduce.blas_core())", OPENBLAS_CORETYPE="Prescott") == "Prescott"
