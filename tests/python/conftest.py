"""Shared inputs for the qpreduce Python tests: seeded random PSD problems."""

import os

import numpy as np
import pytest
import scipy.sparse
import scipy.sparse.linalg

import qpreduce

# scripts/test.sh runs part of this suite against the installed package; it
# sets QPREDUCE_EXPECT_PACKAGE_DIR so that a build tree found first by
# accident fails instead of being tested in its place.
_expected = os.environ.get("QPREDUCE_EXPECT_PACKAGE_DIR")
if _expected and not os.path.realpath(qpreduce.__file__).startswith(os.path.realpath(_expected) + os.sep):
    raise RuntimeError(f"qpreduce imported from {qpreduce.__file__}, expected under {_expected}")


class RandomProblem:
    """Eq. 1 with a random PSD H (n×n, nullity ν, condition 1e3 on its range),
    Gaussian C (n×d), D (n×k) and an in-span demand A = C·A_c, q = D·Y."""

    def __init__(self, n=60, nullity=2, d=8, k=3, m=5, seed=0):
        rng = np.random.default_rng(seed)
        V, _ = np.linalg.qr(rng.standard_normal((n, n)))
        eigenvalues = np.concatenate([np.zeros(nullity), np.geomspace(1e-3, 1.0, n - nullity)])
        H = (V * eigenvalues) @ V.T
        self.H = scipy.sparse.csc_matrix((H + H.T) / 2)
        self.C = rng.standard_normal((n, d))
        self.D = rng.standard_normal((n, k))
        self.A_c = rng.standard_normal((d, m))
        self.A = self.C @ self.A_c
        self.b = rng.standard_normal(m)
        self.Y = rng.standard_normal(k)
        self.q = self.D @ self.Y
        self.n, self.d, self.k, self.m = n, d, k, m

    def kkt_solution(self, A=None, b=None, q=None):
        """X of the full KKT system [[H, A], [Aᵀ, 0]]·[X; Λ] = [q; b] (SciPy)."""
        A = self.A if A is None else A
        b = self.b if b is None else b
        q = self.q if q is None else q
        K = scipy.sparse.bmat([[self.H, scipy.sparse.csc_matrix(A)], [scipy.sparse.csc_matrix(A.T), None]],
                              format="csc")
        return scipy.sparse.linalg.spsolve(K, np.concatenate([q, b]))[: self.n]


@pytest.fixture(params=[0, 1, 2, 3])
def problem(request):
    return RandomProblem(seed=request.param)


def relative_error(x, reference):
    return np.linalg.norm(x - reference) / np.linalg.norm(reference)


def resident_bytes():
    """This process's resident set size (RSS) in bytes."""
    import resource
    with open("/proc/self/statm") as statm:
        pages = int(statm.read().split()[1])
    return pages * resource.getpagesize()


def rss_growth(run, count=10_000, warm_up=1000):
    """How much the RSS grows over run(count), after run(warm_up) has filled
    the allocator pools and loaded code lazily."""
    run(warm_up)
    before = resident_bytes()
    run(count)
    return resident_bytes() - before
