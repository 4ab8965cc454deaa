"""qpreduce.deform.diagnose_mesh: the mesh pre-flight of `qpr check` from Python
(the C++ analysis in plugins/deform/src/mesh/mesh_check.cpp; the binding
only converts)."""
import numpy as np
import pytest

from qpreduce import deform

SQUARE_V = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=float)
SQUARE_F = np.array([[0, 1, 2], [0, 2, 3]], dtype=np.int32)


def test_a_clean_square():
    s = deform.diagnose_mesh(SQUARE_V, SQUARE_F)
    assert s["status"] == "clean"
    assert s["findings"] == []
    assert s["components"] == 1 and not s["anchors_checked"]
    assert s["diagonal"] == pytest.approx(np.sqrt(2.0))


def test_a_sliver_is_a_warning_naming_it():
    V = np.vstack([SQUARE_V, [0.5, -1e-5, 0]])
    F = np.vstack([SQUARE_F, [0, 4, 1]])
    s = deform.diagnose_mesh(V, F)
    assert s["status"] == "warnings"
    [f] = s["findings"]
    assert (f["defect"], f["severity"], f["count"], f["first"]) == ("near_degenerate_element", "warning", 1, [[2]])
    assert "triangle 2 (vertices 0, 4, 1) is nearly degenerate" in f["message"]
    # A stricter threshold lets it pass: the options reach the C++ side.
    assert deform.diagnose_mesh(V, F, near_degenerate_quality=1e-6)["status"] == "clean"


def test_nan_is_a_finding_not_an_exception():
    V = SQUARE_V.copy()
    V[2, 1] = np.nan
    s = deform.diagnose_mesh(V, SQUARE_F)
    assert s["status"] == "errors"
    assert s["findings"][0]["defect"] == "non_finite_coordinate"


def test_unanchored_component_with_anchors_from_a_scenario():
    V = np.vstack([SQUARE_V, SQUARE_V + [10, 0, 0]])
    F = np.vstack([SQUARE_F, SQUARE_F + 4]).astype(np.int32)
    anchored = np.zeros(8, dtype=bool)
    anchored[1] = True
    s = deform.diagnose_mesh(V, F, anchored)
    [f] = s["findings"]
    assert f["defect"] == "unanchored_component" and f["first"] == [[1]]
    assert "connected component 1 (4 vertices, first vertex 4)" in f["message"]
    sc = deform.sel_def_scenario(V, F, [0, 1, 1, 1, 2, 1, 1, 1], np.eye(4))
    held = deform.anchored_vertices(sc)
    assert held.dtype == bool and list(np.flatnonzero(held)) == [0, 4]
    assert deform.diagnose_mesh(V, F, held)["status"] == "clean"


def test_tets_and_argument_errors():
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [0, 0, -1]], dtype=float)
    T = np.array([[0, 1, 2, 3], [0, 1, 2, 4]], dtype=np.int32)
    s = deform.diagnose_mesh(V, T)
    assert s["corners"] == 4
    assert [f["defect"] for f in s["findings"]] == ["inverted_tet"]
    with pytest.raises(ValueError, match=r"V: expected a real array of shape \(n, 3\)"):
        deform.diagnose_mesh(V[:, :2], T)
    with pytest.raises(ValueError, match="E: expected shape"):
        deform.diagnose_mesh(V, T[:, :2])
    with pytest.raises(ValueError, match="anchored: expected 5 flags"):
        deform.diagnose_mesh(V, T, np.ones(3, dtype=bool))
    with pytest.raises(ValueError, match="max_listed must be at least 1"):
        deform.diagnose_mesh(V, T, max_listed=0)


def test_tets_touching_at_one_vertex():
    # Two positive tets sharing vertex 0 and nothing else: one piece of solid each.
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [-1, 0, 0], [0, -1, 0], [0, 0, -1]], dtype=float)
    T = np.array([[0, 1, 2, 3], [0, 5, 4, 6]], dtype=np.int32)
    s = deform.diagnose_mesh(V, T)
    assert [f["defect"] for f in s["findings"]] == ["non_manifold_vertex"]
    assert s["findings"][0]["first"] == [[0]] and s["findings"][0]["severity"] == "warning"
    assert "vertex 0 joins 2 separate groups of tets" in s["findings"][0]["message"]
