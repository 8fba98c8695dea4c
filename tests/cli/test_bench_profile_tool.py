"""Smoke test of selfas_graph/bench/profile.py on the quick scene (a few steps): every part of the table
sums to the profiled total and the kernels are counted; the times are measurements, not checked."""

from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def _tool():
    from selfas_graph.bench import profile

    return profile


def test_profile_table_of_a_few_steps(capsys):
    tool = _tool()
    tool.main(["--scenario", str(ROOT / "scenarios" / "quick.toml"), "--settle", "4", "--steps", "12"])
    out = capsys.readouterr().out
    assert "compiles for" in out and "| total (profiled) |" in out
    rows = [line for line in out.splitlines() if line.startswith("| ") and "ms/step" not in line]
    shares = [float(line.split("|")[3].strip().rstrip(" %")) for line in rows[:-1]]
    assert abs(sum(shares) - 100.0) < 1.0  # each share is rounded to 0.1 %
    assert "kernel calls per 1000 steps:" in out and "ab4_step" in out


def test_team_table(capsys):
    """``--team --phases``: both ways timed, each phase too; TEAM_TIPS and the calls put back."""
    import platform

    import numba
    import pytest

    from selfas_graph.model import compiled

    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("numba has one thread here")

    tool = _tool()
    threads, limit = numba.get_num_threads(), compiled.TEAM_TIPS
    try:
        tool.main(
            [
                "--team",
                "--scenario",
                str(ROOT / "scenarios" / "quick.toml"),
                "--settle",
                "4",
                "--steps",
                "8",
                "--rounds",
                "1",
                "--phases",
            ]
        )
    finally:
        numba.set_num_threads(threads)
    out = capsys.readouterr().out
    assert "| on all threads |" in out and "| on one thread |" in out and "speed-up of the whole step (wall):" in out
    assert compiled.TEAM_TIPS == limit
    # --phases: each kind of phase both ways and the whole call; the compiled calls put back as they were
    assert compiled.CompiledSteps.advance.__name__ == "advance"
    if platform.machine().lower() in ("x86_64", "amd64"):
        for row in (
            "| forces |",
            "| AB4 update and powers |",
            "| constraint |",
            "| between phases |",
            "| whole call |",
            "| the call, wall clock (fork and join of the threads, Python) |",
        ):
            assert row in out, row

        def times(name):
            line = next(x for x in out.splitlines() if x.startswith(f"| {name} |"))
            return [float(v) for v in line.split("|")[2:4]]

        # the wall clock around a call holds the leading thread's compiled part of it (the cycle counter's
        # rate is measured over the same turns, to well under the Python around each call)
        for wall, compiled_part in zip(
            times("the call, wall clock (fork and join of the threads, Python)"), times("whole call")
        ):
            assert wall > compiled_part > 0.0
    else:
        assert "x86-64 only" in out
    with pytest.raises(SystemExit, match="--phases times the phases of --team"):
        tool.main(["--phases", "--scenario", str(ROOT / "scenarios" / "quick.toml")])


def test_team_refuses_a_thread_count_numba_cannot_give():
    import numba
    import pytest

    tool = _tool()
    for bad, message in (
        (0, "--threads must be a positive number"),
        (numba.config.NUMBA_NUM_THREADS + 1, "--team needs"),
    ):
        with pytest.raises(SystemExit, match=message):
            tool.main(["--team", "--threads", str(bad), "--scenario", str(ROOT / "scenarios" / "quick.toml")])


def test_fused_kernels_table(capsys):
    tool = _tool()
    tool.main(["--kernels", "--rounds", "1", "--steps", "10"])
    out = capsys.readouterr().out
    assert "| channel sum of 10 channels and 6 powers |" in out and "| extrapolation of 4 held arrays |" in out


def test_every_function_falls_in_one_part():
    tool = _tool()
    assert tool.part_of(("/x/selfas_graph/kernels/tips.py", 1, "tip_tip_direct")).startswith("tip-tip far")
    assert tool.part_of(("/x/selfas_graph/kernels/currents.py", 1, "rod_current_field")).startswith("current field at")
    assert tool.part_of(("/x/selfas_graph/kernels/cells.py", 1, "_row_fill")) == "neighbour-list builds"
    assert tool.part_of(("~", 0, "<built-in method numpy.einsum>")) == "numpy and other"


def test_checks_tool_times_both_checks(capsys):
    from selfas_graph.bench import checks as tool

    got = tool.main(
        ["--scenario", str(ROOT / "scenarios" / "quick.toml"), "--settle", "4", "--repeat", "2", "--calls", "2"]
    )
    assert len(got) == 2 and all(v[0] > 0 and v[1] > 0 for v in got.values())
    assert "compiles for" in capsys.readouterr().out


_REPORT = """# Samples: 100 of event 'cpu-clock'
#
#       Samples  Shared Object
# ............  .............
#
            80  /tmp/perf-4242.map
             6  /root/.pyenv/versions/3.11.7/lib/libpython3.11.so.1.0
             5  /v/lib/python3.11/site-packages/numpy/_core/_multiarray_umath.cpython-311-x86_64-linux-gnu.so
             1  /v/lib/python3.11/site-packages/numba/_dispatcher.cpython-311-x86_64-linux-gnu.so
             2  /v/lib/python3.11/site-packages/scipy/sparse/linalg/_dsolve/_superlu.cpython-311-x86_64-linux-gnu.so
             4  /usr/lib/x86_64-linux-gnu/libc.so.6
             2  [kernel.kallsyms]
"""


def test_sampled_shares_sort_each_shared_object_into_its_part():
    tool = _tool()
    counts = tool.parse_dso_samples(_REPORT)
    assert sum(counts.values()) == 100 and counts["/tmp/perf-4242.map"] == 80
    shares = tool.sampled_shares(counts)
    assert shares["compiled kernels (numba)"] == 0.80
    assert shares["Python interpreter"] == 0.06 and shares["numpy"] == 0.05
    assert shares["numba's dispatch, runtime and threads"] == 0.01
    assert shares["scipy (the circuit's sparse solve)"] == 0.02
    assert shares["C library (allocation, memory copies, maths)"] == 0.04
    assert shares["operating system"] == 0.02 and shares["other"] == 0.0
    assert tool.sampled_part_of("[JIT] tid 4242") == "compiled kernels (numba)"
    assert tool.sampled_part_of("/usr/bin/python3.11") == "Python interpreter"


def test_sampled_profile_or_its_reason(capsys):
    """With perf installed and allowed, the sampled table; without, one line saying why (no traceback)."""
    tool = _tool()
    tool.main(["--scenario", str(ROOT / "scenarios" / "quick.toml"), "--settle", "4", "--steps", "40", "--sample"])
    out = capsys.readouterr().out
    assert ("| compiled kernels (numba) |" in out and "Python and numpy (" in out) or "no sampled profile: " in out


def test_the_parts_a_function_is_counted_in():
    """cProfile's keys (path, line, function) to the table's parts: the event path's kernels and scipy's
    sparse LU (its factorisation and its solve) in the graph and circuit, the contact search's close-pair
    kernels in the search (the brake calls them from Python only from PARALLEL_ROWS tips on)."""
    part_of = _tool().part_of
    kernels = "/x/selfas_graph/kernels/"
    cases = {
        ("~", 0, "<built-in method scipy.sparse.linalg._dsolve._superlu.gstrf>"): "graph and circuit on events",
        ("~", 0, "<method 'solve' of 'SuperLU' objects>"): "graph and circuit on events",
        (kernels + "graph.py", 1, "filament_rods"): "graph and circuit on events",
        ("/x/selfas_graph/model/contactset.py", 1, "apply"): "graph and circuit on events",
        (kernels + "contacts.py", 1, "contact_news"): "contact search and events",
        (kernels + "contacts.py", 1, "close_pairs"): "contact search and events",
        (kernels + "brakes.py", 1, "brake_close_pairs_exact"): "split brake (close pairs, exact brake)",
        (kernels + "integrate.py", 1, "ab4_step"): "cheap O(n) kernels (walls, fields, integration, bonds)",
    }
    for key, part in cases.items():
        assert part_of(key) == part, key


def test_a_checkpoint_profiled_at_another_time_step(tmp_path, capsys):
    """``--checkpoint X --set integrator.dt=...`` ended in from_snapshot's ValueError (a snapshot continued at
    another time step): the tool now continues it at that step, its history forgotten, and says so."""
    from selfas_graph.cli.main import main as cli

    run = tmp_path / "run.h5"
    scene = str(ROOT / "scenarios" / "quick.toml")
    argv = ["simulate", scene, "-o", str(run), "--set", "rods.count=20", "--t-end", "0.02", "--progress", "none"]
    assert cli(argv) in (0, None)
    capsys.readouterr()
    ckpt = str(tmp_path / "run.checkpoint.h5")
    _tool().main(["--checkpoint", ckpt, "--set", "integrator.dt=5e-4", "--steps", "4"])
    assert "at integrator.dt = 0.0005, started again with RK4" in capsys.readouterr().out
