"""Smoke test of selfas_graph/bench/line_charge.py on a small Fig. 8 scene: a table row per number of
points, the errors against the converged integral falling as the points grow (the times are
measurements, not checked), and a scene without the line charge refused."""

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def _tool():
    from selfas_graph.bench import line_charge

    return line_charge


def test_points_table_on_a_fig8_state(capsys):
    fig8 = str(ROOT / "scenarios" / "fig8_quick.toml")
    _tool().main(["--scenario", fig8, "--set", "rods.count=40", "--points", "16", "4", "8", "--rounds", "1"])
    out = capsys.readouterr().out
    assert "compiles for" in out and "40 rods" in out
    rows = [line.split("|") for line in out.splitlines() if line.startswith("| ") and "quadrature" not in line]
    largest = {int(r[1]): float(r[6]) for r in rows}
    assert set(largest) == {4, 8, 16}
    # Gauss-Legendre in the asinh variable converges fast: each doubling of the points gains much
    assert largest[16] < largest[8] < largest[4]


def test_a_scene_without_the_line_charge_is_refused():
    with pytest.raises(SystemExit, match="no \\[forces.external_dipole\\]"):
        _tool().main(["--scenario", str(ROOT / "scenarios" / "quick.toml"), "--set", "rods.count=20", "--rounds", "1"])


def test_a_missing_checkpoint_or_a_bad_scene_is_refused_by_name(tmp_path):
    with pytest.raises(SystemExit, match="no such checkpoint file"):
        _tool().main(["--checkpoint", str(tmp_path / "none.checkpoint.h5")])
    with pytest.raises(SystemExit, match="rods.count"):
        _tool().main(["--scenario", str(ROOT / "scenarios" / "fig8_quick.toml"), "--set", "rods.count=-3"])
