"""scripts/plots.py: the quality study's sweep figures (matplotlib), on made-up sweeps."""

import os
import sys

import pytest

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "scripts"))
plots = pytest.importorskip("plots")


@pytest.mark.parametrize("ext", ["png", "svg"])
def test_line_plot_writes_two_panels_with_targets(tmp_path, ext):
    ratio = {"cactus": [(5, 1.2), (9, 1.1), (27, 1.02)], "cylinder": [(5, 1.5), (27, 1.05)]}
    rms = {"cactus": [(5, 2.0), (9, 1.0), (27, 0.3)], "cylinder": [(5, 30.0), (27, 0.05)]}
    path = str(tmp_path / f"sweep.{ext}")
    plots.line_plot(path, "Rotational proxy sweep", "rotational proxies d",
                    [("energy ratio", ratio, "auto"), ("RMS %", rms, "auto")], ["cactus", "cylinder", "absent"],
                    logx=True, hlines={0: 1.1, 1: 1.0}, styles={"cylinder": ("#d62728", True)})
    assert os.path.getsize(path) > 10_000
