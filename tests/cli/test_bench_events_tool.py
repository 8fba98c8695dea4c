"""Smoke test of selfas_graph/bench/events.py, its three parts at small sizes on the quick scene: each
prints its table, and part (c) checks its classifications against the scipy/networkx peer. The times
are measurements, not checked."""

from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
QUICK = str(ROOT / "scenarios" / "quick.toml")


def test_every_part_prints_its_table(capsys):
    from selfas_graph.bench import events

    events.main(
        ["--scenario", QUICK, "--settle", "300", "--steps", "30", "--sizes", "1000", "--batch", "10", "--repeat", "1",
         "--run-steps", "300", "--peer-graphs", "3"]
    )  # fmt: skip
    out = capsys.readouterr().out
    # (a): the frozen scenes stay still (the tool asserts no event there) and every row is printed
    assert "(a) contact detection + events" in out and "| frozen scene" in out and "`search_news`" in out
    # (b): one row for 1000 rods
    assert "(b) ConnectivityGraph" in out and "\n| 1000 |" in out
    # (c): the network's work on the steps with events, timed where the run calls it
    assert "(c) topology and circuit per event" in out
    for row in ("Network.update on a step with events", "ContactSet.apply", "classify_rods (all of it)",
                "Network.solve (circuit)"):  # fmt: skip
        assert row in out
    calls = {}
    for line in out.splitlines():
        cells = [c.strip() for c in line.split("|")]
        if len(cells) == 6 and cells[1].startswith(("Network.update", "ContactSet.apply", "classify_rods")):
            calls[cells[1].split(" ")[0]] = float(cells[2])
    assert calls["Network.update"] > 0, "the quick scene's first 600 steps have contact events"
    assert calls["ContactSet.apply"] == calls["Network.update"] == calls["classify_rods"]
    assert "same results checked" in out
