"""Hostile input: generated scenario files, command-line arguments and run files.

The contract of every subcommand (README, ``cli/main.py``): bad input gives exit code 2 and
a message on stderr naming the problem, never a Python traceback; a numerical failure gives
exit code 3; an existing file (output, scenario, run file, checkpoint) is never damaged and
a failed run (exit 2) creates no output file. Each property test below generates inputs with
hypothesis (derandomized, so CI sees the same cases every run; no example database is
written) and checks that contract through ``main([...])`` called in-process.

Generated cases per run (``max_examples`` of each test; hypothesis may stop a test earlier
once it has tried every distinct input of a small search space):

==========================================  =====
test_generated_scenario_files_dry_run         400
test_generated_scenario_files_real_run         60
test_generated_set_overrides                  200
test_generated_t_end                           60
test_generated_simulate_argv                  100
test_generated_output_paths                    60
test_hostile_files_to_topology                 80
test_generated_topology_arguments              40
test_hostile_files_to_plot                     40
test_generated_plot_arguments                  15
test_hostile_checkpoints_to_resume             50
test_hostile_run_files_to_resume               50
test_generated_magnitudes_in_every_numeric_key 150
test_generated_bit_flips_in_a_checkpoint        60
test_generated_moved_folders_and_foreign_...    20
==========================================  =====
total                                        1385

Disk-full, quota and kill cases run in subprocesses in ``tests/validation/test_reliability.py`` (an I/O
failure may leave HDF5 in a state that only a process exit ends).

The number of cases that actually ran is printed at the end of the module (``hostile input:
N generated cases``); it is at most the total above.

The 26 bugs these tests found (tracebacks on absurd values, damaged files on resume and
output-name mistakes) are fixed; each is pinned by a ``test_bug_*`` test in
``tests/validation/test_hostile_bugs.py`` with its input and the expected behaviour. A new bug is written
the same way, first marked ``xfail(strict=True)`` until it is fixed. The property tests leave out
only inputs that are slow rather than wrong (``hostile.known_bug_scenario``: more than 500 rods to
place). The helpers and strategies of both modules are in ``tests/hostile.py``, their fixtures
(``real_run``, ``workdir``) in ``tests/conftest.py``.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import shutil
import stat
import tempfile
import tomllib
import typing
from pathlib import Path

import pytest
from hypothesis import event, given, note, settings
from hypothesis import strategies as st

from hostile import (
    BASE,
    BASE_TEXT,
    CASES,
    GIANT_INTS,
    GRAPH_PATHS,
    HOSTILE,
    LEAVES,
    SECTIONS,
    check_contract,
    cli,
    example_dir,
    has_items,
    has_run_markers,
    hostile_files,
    hostile_floats,
    hostile_values,
    key_names,
    known_bug_scenario,
    make_hostile_file,
    nameless,
    non_finite_datasets,
    parse,
    rplus_open_changes,
    scenario_file,
    scenario_files,
    skip_known,
    snapshot_of,
    toml_str,
    toml_value,
    tree,
)
from selfas_graph import RunFile
from selfas_graph.io.checkpoint import FORMAT as CHECKPOINT_FORMAT
from selfas_graph.io.scenario import _apply_override  # to know what a --set list makes of the scenario
from selfas_graph.model import params as P


@pytest.fixture(scope="module", autouse=True)
def _report_cases(request):
    yield
    total = sum(CASES.values())
    line = "hostile input: %d generated cases (%s)" % (total, ", ".join(f"{k} {v}" for k, v in sorted(CASES.items())))
    reporter = request.config.pluginmanager.get_plugin("terminalreporter")
    if reporter is not None:
        reporter.write_line("\n" + line)
    else:  # pragma: no cover
        print(line)


# --------------------------------------------------------------------------- generated scenario files


def _plan(out: str) -> dict | None:
    """The JSON plan printed by ``--dry-run``."""
    k = out.find("\n{")
    if k < 0:
        return None
    try:
        return json.loads(out[k + 1 :])
    except json.JSONDecodeError:
        return None


@settings(max_examples=400, **HOSTILE)
@given(case=scenario_files(), with_o=st.booleans())
def test_generated_scenario_files_dry_run(case, with_o, workdir, capsys):
    """400 generated scenario files (mutated values of every type at every level, values of the
    right type at and beyond the edges of their range, unknown keys, missing sections, NaN/inf,
    huge/negative/zero numbers, truncated TOML, junk and non-UTF-8 bytes, empty files) through
    ``simulate --dry-run`` with or without ``-o``: exit 0, 2 or 3, a message with 2, no
    traceback, nothing written and the scenario file unchanged."""
    how, data = case
    raw = parse(data)
    bug = known_bug_scenario(raw)
    note(f"how={how} bug={bug}\n{data[:3000]!r}")
    event(f"file: {how}")
    skip_known(bug)
    CASES["scenario_dry_run"] += 1
    d = example_dir(workdir)
    scen = d / "s.toml"
    scen.write_bytes(data)
    before = tree(d)
    res = cli(capsys, "simulate", scen, *(["-o", d / "out.h5"] if with_o else []), "--dry-run")
    check_contract(res)
    if raw is None:
        assert res.code == 2, "a file that is not UTF-8 TOML must be refused"
    assert tree(d) == before, "--dry-run wrote or changed a file"


@settings(max_examples=60, **HOSTILE)
@given(case=scenario_files())
def test_generated_scenario_files_real_run(case, workdir, capsys):
    """60 generated scenario files as above; those whose dry-run plan is small (<= 20 steps,
    <= 20 rods) are also run for real: exit 0/2/3 without traceback, no output file after
    exit 2, a readable run file after exit 0, the scenario file unchanged."""
    how, data = case
    raw = parse(data)
    bug = known_bug_scenario(raw, real=True)
    note(f"how={how} bug={bug}\n{data[:3000]!r}")
    event(f"file: {how}")
    skip_known(bug)
    CASES["scenario_real_run"] += 1
    d = example_dir(workdir)
    scen = d / "s.toml"
    scen.write_bytes(data)
    out = d / "out.h5"
    dry = cli(capsys, "simulate", scen, "-o", out, "--dry-run")
    check_contract(dry)
    plan = _plan(dry.out) if dry.code == 0 else None
    if not plan or plan["steps"] > 20 or plan["rods"] > 20:
        event("dry run only")
        return
    event("real run")
    before = tree(d)
    res = cli(capsys, "simulate", scen, "-o", out, "--progress", "none")
    check_contract(res)
    assert scen.read_bytes() == data
    if res.code == 2:
        assert tree(d) == before, "exit 2 but files were written or changed"
    else:
        with RunFile(out) as run:
            assert run.n_frames >= 1


# --------------------------------------------------------------------------- generated CLI arguments

set_keys = st.one_of(
    st.sampled_from([".".join(p) for p in LEAVES + SECTIONS[1:]]),
    st.sampled_from(
        [
            "",
            ".",
            "a..b",
            " rods.count ",
            "rods.count.x",
            "forces.yukawa.x.y",
            "output.file.z",
            "rods.",
            ".rods",
            "run.t_end=1",
            "scenario",
            "forces",
        ]
    ),
    st.lists(key_names, min_size=1, max_size=3).map(".".join),
)
set_values = st.one_of(
    hostile_values.map(toml_value),
    st.text(st.characters(exclude_categories=("Cs",)), max_size=12),
    st.sampled_from(
        [
            "",
            "=",
            "[",
            "{",
            "nan",
            "-inf",
            "1e999",
            "0x10",
            "1_000",
            "true",
            '"unterminated',
            "{a = 1}",
            "[" * 60 + "]" * 60,
            "1\nrods = 3",
            "'literal'",
            "2024-01-01",
            "[[0, 1], [0, 1], [0, 1]]",
        ]
    ),
)
set_items = st.one_of(
    st.tuples(set_keys, set_values).map(lambda kv: f"{kv[0]}={kv[1]}"),
    st.text(st.characters(exclude_categories=("Cs",)), max_size=12),  # often without "="
)


def _effective(overrides=(), t_end=None):
    raw = tomllib.loads(BASE_TEXT)
    for item in overrides:
        if _apply_override(raw, item):
            return None  # the loader reports the override itself
    if t_end is not None and isinstance(raw.get("run"), dict):
        raw["run"]["t_end"] = t_end
    return raw


@settings(max_examples=200, **HOSTILE)
@given(items=st.lists(set_items, min_size=1, max_size=3))
def test_generated_set_overrides(items, workdir, capsys, real_run):
    """200 generated lists of ``--set KEY=VALUE`` (schema keys, unknown and malformed keys,
    values of every TOML type, NaN/inf, unparsable text, items without '=') with ``--dry-run``:
    exit 0/2/3, a message with 2, no traceback, nothing written."""
    bug = known_bug_scenario(_effective(items))
    note(f"bug={bug}")
    skip_known(bug)
    CASES["set_overrides"] += 1
    d = example_dir(workdir)
    before = tree(d)
    argv = ["simulate", real_run["scenario"], "-o", d / "out.h5", "--dry-run"]
    for item in items:
        argv += [f"--set={item}"]
    res = cli(capsys, *argv)
    check_contract(res)
    assert tree(d) == before
    assert real_run["scenario"].read_text() == BASE_TEXT


t_end_values = st.one_of(
    hostile_floats.map(repr),
    st.sampled_from(["-1", "0", "-0", "nan", "NaN", "inf", "-inf", "1e999", "", " ", "abc", "0x1p-3", "1_0", "\x00"]),
    st.text(st.characters(exclude_categories=("Cs",)), max_size=8),
)


@settings(max_examples=60, **HOSTILE)
@given(value=t_end_values)
def test_generated_t_end(value, workdir, capsys, real_run):
    """60 generated ``--t-end`` values (negative, zero, NaN, inf, huge, tiny, non-numbers) with
    ``--dry-run``; those whose plan is at most 20 steps also run for real: exit 0/2/3, no
    traceback, no output file after exit 2."""
    try:
        t = float(value)
    except ValueError:
        t = None
    bug = known_bug_scenario(_effective(t_end=t), real=True) if t is not None else None
    note(f"bug={bug}")
    skip_known(bug)
    CASES["t_end"] += 1
    d = example_dir(workdir)
    out = d / "out.h5"
    res = cli(capsys, "simulate", real_run["scenario"], "-o", out, f"--t-end={value}", "--dry-run")
    check_contract(res)
    assert not out.exists()
    if t is None:
        assert res.code == 2
    plan = _plan(res.out) if res.code == 0 else None
    if plan and plan["steps"] <= 20:
        res = cli(capsys, "simulate", real_run["scenario"], "-o", out, f"--t-end={value}", "--progress", "none")
        check_contract(res)
        assert out.exists() == (res.code != 2)


simulate_options = st.one_of(
    st.tuples(
        st.just("-o"),
        st.sampled_from(
            ["out.h5", "/", ".", "", "sub/out.h5", "SCEN", "adir", "out.checkpoint.h5", "x", "adir/", "-", "out.h5/"]
        ),
    ),
    st.tuples(st.just("--resume"), st.sampled_from([".", "/", "", "out.h5", "SCEN", "adir", "missing.h5", "-"])),
    st.tuples(st.just("--set"), set_items),
    st.tuples(st.just("--t-end"), st.sampled_from(["0.001", "0", "-1", "nan", "inf", "abc", "", "1e-12"])),
    st.tuples(st.just("--progress"), st.sampled_from(["auto", "bar", "lines", "none", "sometimes", ""])),
    st.tuples(st.sampled_from(["--dry-run", "--force", "--bogus", "-h", "--", "--frame"])),
)


def _option_value(argv, *names):
    """The value argparse would keep for an option (the last one given), or None."""
    value = None
    for k, tok in enumerate(argv[:-1]):
        if tok in names:
            value = argv[k + 1]
    return value


@settings(max_examples=100, **HOSTILE)
@given(
    positional=st.sampled_from([None, "SCEN", "missing.toml", ".", "", "-", "adir", "SCEN SCEN"]),
    options=st.lists(simulate_options, max_size=5),
    order=st.randoms(use_true_random=False),
)
def test_generated_simulate_argv(positional, options, order, workdir, capsys, real_run):
    """100 generated argument lists of ``simulate``: a scenario (or a missing file, a directory, '.',
    '' or two scenarios) with options in random order and with hostile values (-o to '/', '.', '',
    a directory, the scenario; --resume of nothing or of a directory; malformed --set; missing option
    values; unknown options): exit 0/2/3, argparse's usage errors as exit 2, no traceback; the
    scenario is never changed and exit 2 leaves the folder as it was."""
    groups = [list(opt) for opt in options] + ([] if positional is None else [positional.split(" ")])
    order.shuffle(groups)
    argv = [tok for group in groups for tok in group]
    out, resume = _option_value(argv, "-o", "--output"), _option_value(argv, "--resume")
    bug = "test_bug_output_path_without_a_name" if nameless(out) or (resume and nameless(resume)) else None
    note(f"argv={argv} bug={bug}")
    skip_known(bug)
    CASES["simulate_argv"] += 1
    d = example_dir(workdir)
    os.chdir(d)
    shutil.copy(real_run["scenario"], d / "SCEN")
    (d / "adir").mkdir()
    before = tree(d)
    res = cli(capsys, "simulate", *argv)
    check_contract(res)
    assert (d / "SCEN").read_text() == BASE_TEXT or "--force" in argv
    if res.code == 2:
        assert tree(d) == before, "exit 2 but files were written or changed"


name_parts = st.text(st.characters(categories=("L", "N"), include_characters="_-. "), min_size=1, max_size=8).filter(
    lambda s: s not in (".", "..")
)
output_cases = st.one_of(
    st.tuples(st.just("missing_folder"), st.lists(name_parts, min_size=1, max_size=3)),
    st.tuples(st.just("file_as_folder"), name_parts),
    st.tuples(st.just("existing"), st.binary(max_size=200)),
    st.tuples(st.just("existing_run")),
    st.tuples(st.just("directory"), st.booleans()),
    st.tuples(st.just("scenario_itself")),
    st.tuples(
        st.just("output_file_key"),
        st.one_of(
            st.sampled_from(["", ".", "..", "a", "adir", "s.toml", "a\x00b.h5", " ", "x.h5 ", "\u00e9.h5"]),
            st.text(st.characters(exclude_categories=("Cs",), exclude_characters="/"), max_size=8),
        ),
    ),
)


@settings(max_examples=60, **HOSTILE)
@given(case=output_cases)
def test_generated_output_paths(case, workdir, capsys, real_run):
    """60 generated output targets: ``-o`` into missing folders, below a regular file, onto an existing
    file (random bytes, a real run file, the scenario itself) without --force, onto a directory:
    exit 2 with a message, no traceback, no file created and every existing file byte-identical;
    and ``output.file`` names (no -o; random text, '', '..', an existing file or directory) in real
    runs: exit 0/2/3, no existing file changed. (With --force a file may be replaced: that is what
    --force is for.)"""
    d = example_dir(workdir)
    scen = d / "s.toml"
    scen.write_text(BASE_TEXT)
    kind, force = case[0], False
    if kind == "missing_folder":
        out = d.joinpath("missing", *case[1], "x.h5")
    elif kind == "file_as_folder":
        (d / "afile").write_bytes(b"a regular file")
        out = d / "afile" / case[1]
    elif kind == "existing":
        out = d / "old.h5"
        out.write_bytes(case[1])
    elif kind == "existing_run":
        out = d / "old.h5"
        out.write_bytes(real_run["run_bytes"])
    elif kind == "directory":
        out = d / "adir"
        out.mkdir()
        (out / "inside.txt").write_text("keep me")
        force = case[1]
    elif kind == "scenario_itself":
        out = scen
    else:  # no -o: the scenario's output.file names the output (relative, no '/': it stays in d)
        name = case[1]
        note(f"output.file={name!r}")
        CASES["output_paths"] += 1
        (d / "a").write_bytes(b"an existing file called a")
        (d / "adir").mkdir()
        scen.write_text(BASE_TEXT + f"file = {toml_str(name)}\n")  # the last table of BASE_TEXT is [output]
        before = tree(d)
        os.chdir(d)
        res = cli(capsys, "simulate", scen.name, "--progress", "none")
        check_contract(res)
        after = tree(d)
        assert {k: v for k, v in after.items() if k in before} == before, "an existing file was changed"
        if res.code == 2:
            assert after == before
        return
    CASES["output_paths"] += 1
    before = tree(d)
    argv = ["simulate", scen, "-o", out, "--progress", "none"] + (["--force"] if force else [])
    res = cli(capsys, *argv)
    check_contract(res, allowed=(2,))
    assert tree(d) == before


def test_read_only_output_folder(workdir, capsys, real_run):
    """``-o`` into a folder without write permission: exit 2 naming the folder, nothing created."""
    d = workdir / "ro"
    d.mkdir()
    d.chmod(0o500)
    try:
        if os.access(d, os.W_OK):
            pytest.skip("running as root (or similar): a 0o500 folder is still writable")
        res = cli(capsys, "simulate", real_run["scenario"], "-o", d / "x.h5", "--progress", "none")
        check_contract(res, allowed=(2,))
        assert "not writable" in res.err
        assert list(d.iterdir()) == []
    finally:
        d.chmod(stat.S_IRWXU)


@settings(max_examples=80, **HOSTILE)
@given(spec=hostile_files, json_out=st.booleans())
def test_hostile_files_to_topology(spec, json_out, workdir, capsys, real_run):
    """80 generated files given to ``topology`` (truncated copies of a real run, junk bytes with and
    without the HDF5 signature, empty file, a directory, a text file, foreign HDF5 files with random
    groups and datasets, some named like a run's): exit 2 with a message, no traceback, no stdout,
    the file byte-identical afterwards."""
    bug = "test_bug_topology_foreign_graph" if has_run_markers(spec) and has_items(spec, *GRAPH_PATHS) else None
    note(f"bug={bug}")
    skip_known(bug)
    CASES["topology_files"] += 1
    d = example_dir(workdir)
    f = make_hostile_file(spec, d / "run.h5", real_run["run_bytes"])
    before = snapshot_of(f)
    res = cli(capsys, "topology", f, *(["--json"] if json_out else []))
    check_contract(res, allowed=(2,))
    assert res.out == ""
    assert snapshot_of(f) == before


@settings(max_examples=40, **HOSTILE)
@given(
    frame=st.one_of(st.none(), st.integers(-10, 10), st.sampled_from(GIANT_INTS)),
    time=st.one_of(st.none(), hostile_floats),
    events=st.one_of(st.none(), st.integers(-5, 5), st.sampled_from(GIANT_INTS)),
    json_out=st.booleans(),
    junk=st.sampled_from([None, "x", "1.5", ""]),
)
def test_generated_topology_arguments(frame, time, events, json_out, junk, capsys, real_run):
    """40 generated argument sets of ``topology`` on a real run (frames in and out of range, huge,
    --time NaN/inf/huge/negative, --events of any size, unparsable values): exit 0 or 2, no
    traceback, strict JSON with --json, the run file byte-identical."""
    CASES["topology_args"] += 1
    argv = ["topology", real_run["run"]]
    if frame is not None and time is None:
        argv.append(f"--frame={frame}")
    if time is not None:
        argv.append(f"--time={time!r}")
    if events is not None:
        argv.append(f"--events={events}")
    if junk is not None:
        argv.append(f"--frame={junk}" if time is None and frame is None else f"--events={junk}")
    if json_out:
        argv.append("--json")
    res = cli(capsys, *argv)
    check_contract(res, allowed=(0, 2))
    if res.code == 0 and json_out:
        json.loads(res.out, parse_constant=lambda tok: pytest.fail(f"non-standard JSON token {tok}"))
    assert real_run["run"].read_bytes() == real_run["run_bytes"]


@settings(max_examples=40, **HOSTILE)
@given(spec=hostile_files, kind=st.sampled_from(["snapshot", "density", "field", "flux", "timeline"]))
def test_hostile_files_to_plot(spec, kind, workdir, capsys, real_run):
    """40 generated files (as for topology) given to ``plot --kind KIND``: exit 2 with a message, no
    traceback, no PNG written, the file byte-identical."""
    bug = "test_bug_plot_foreign_file_with_run_layout" if has_run_markers(spec) else None
    note(f"bug={bug}")
    skip_known(bug)
    CASES["plot_files"] += 1
    d = example_dir(workdir)
    f = make_hostile_file(spec, d / "run.h5", real_run["run_bytes"])
    before = tree(d)
    res = cli(capsys, "plot", f, "--kind", kind, "-o", d / "fig.png", "--dpi", "20")
    check_contract(res, allowed=(2,))
    assert tree(d) == before


@settings(max_examples=15, **HOSTILE)
@given(
    kind=st.sampled_from(["snapshot", "density", "field", "flux", "timeline"]),
    r_max=st.one_of(st.none(), st.sampled_from([0.0, -1.0, math.nan, 1e-300, 0.5, 3.0, 1e6])),
    planes=st.one_of(st.none(), st.lists(st.floats(-1e6, 1e6), min_size=1, max_size=4)),
    bins=st.one_of(st.none(), st.integers(-3, 200)),
    n_phi=st.one_of(st.none(), st.integers(-3, 500)),
    z_mext=st.one_of(st.none(), st.sampled_from([0.0, math.nan, math.inf, -2.0, 1e-300, 10.0])),
    dpi=st.integers(10, 60),
    frame=st.one_of(st.none(), st.integers(-5, 5)),
)
def test_generated_plot_arguments(kind, r_max, planes, bins, n_phi, z_mext, dpi, frame, workdir, capsys, real_run):
    """15 generated option sets of ``plot`` on a real run (--r-max zero/negative/NaN/tiny/huge, finite
    --planes, --bins and --n-phi below 1 and up to hundreds, --z-mext zero/NaN/inf, frames in and out of
    range, dpi 10..60): exit 0 or 2, no traceback, a PNG only after exit 0, the run file unchanged.
    (Infinite --r-max, non-finite --planes and out-of-range --dpi are the test_bug_* tests below.)"""
    CASES["plot_args"] += 1
    d = example_dir(workdir)
    png = d / "fig.png"
    argv = ["plot", real_run["run"], "--kind", kind, "-o", png, f"--dpi={dpi}"]
    for opt, value in (
        ("--r-max", r_max),
        ("--bins", bins),
        ("--n-phi", n_phi),
        ("--z-mext", z_mext),
        ("--frame", frame),
    ):
        if value is not None:
            argv.append(f"{opt}={value!r}")
    if planes:
        argv += ["--planes", *[repr(z) for z in planes]]
    res = cli(capsys, *argv)
    check_contract(res, allowed=(0, 2))
    assert png.exists() == (res.code == 0)
    assert real_run["run"].read_bytes() == real_run["run_bytes"]


@settings(max_examples=50, **HOSTILE)
@given(spec=hostile_files)
def test_hostile_checkpoints_to_resume(spec, workdir, capsys, real_run):
    """50 generated files (as above, truncations of a real checkpoint) given to ``simulate --resume``
    as the checkpoint: exit 2 with a message, no traceback, the file byte-identical, nothing
    created, and the real run the checkpoint names untouched."""
    bug = (
        "test_bug_checkpoint_with_missing_groups"
        if spec[0] == "foreign" and spec[2].get("format") == CHECKPOINT_FORMAT
        else None
    )
    note(f"bug={bug}")
    skip_known(bug)
    CASES["resume_checkpoints"] += 1
    d = example_dir(workdir)
    ckpt = make_hostile_file(spec, d / "run.checkpoint.h5", real_run["checkpoint_bytes"])
    before = tree(d)
    res = cli(capsys, "simulate", "--resume", ckpt, "--progress", "none")
    check_contract(res, allowed=(2,))
    assert tree(d) == before
    assert real_run["run"].read_bytes() == real_run["run_bytes"]


@settings(max_examples=50, **HOSTILE)
@given(spec=hostile_files, t_end=st.sampled_from([None, "0.003"]))
def test_hostile_run_files_to_resume(spec, t_end, workdir, capsys, real_run):
    """50 generated files (as above) given to ``simulate --resume CHECKPOINT -o FILE`` as the run file
    to continue, with a valid checkpoint: exit 2 with a message, no traceback, the file
    byte-identical (a failed resume must not touch it)."""
    d = example_dir(workdir)
    f = make_hostile_file(spec, d / "target.h5", real_run["run_bytes"])
    bug = None
    if rplus_open_changes(f):
        bug = "test_bug_failed_resume_rewrites_the_file"
    elif has_items(spec, "particles/tips/position/step"):
        bug = "test_bug_resume_into_a_file_of_another_layout"
    note(f"bug={bug}")
    skip_known(bug)
    CASES["resume_run_files"] += 1
    ckpt = d / "good.checkpoint.h5"
    ckpt.write_bytes(real_run["checkpoint_bytes"])
    before = tree(d)
    res = cli(
        capsys, "simulate", "--resume", ckpt, "-o", f, "--progress", "none", *([f"--t-end={t_end}"] if t_end else [])
    )
    check_contract(res, allowed=(2,))
    assert tree(d) == before
    assert real_run["run"].read_bytes() == real_run["run_bytes"]


# --------------------------------------------------------------------------- magnitudes, checkpoints, moves


def _numeric_keys():
    """Every numeric key of the schema: (dotted path, type, field)."""
    from selfas_graph.io.scenario import unwrap_optional

    out = []

    def walk(cls, prefix):
        hints = typing.get_type_hints(cls)
        for f in dataclasses.fields(cls):
            tp, _ = unwrap_optional(hints[f.name])
            if dataclasses.is_dataclass(tp):
                walk(tp, prefix + f.name + ".")
            elif tp in (float, int, tuple):
                out.append((prefix + f.name, tp, f))

    walk(P.Parameters, "")
    return out


NUMERIC_KEYS = _numeric_keys()
#: tiny and huge magnitudes, at and beyond the documented 1e-30..1e30 and at the ends of double precision
MAGNITUDES = [
    "5e-324",
    "1e-310",
    "1e-300",
    "1e-31",
    "1e-30",
    "1e30",
    "1e31",
    "1e200",
    "1e308",
    "-1e30",
    "-1e308",
    "-5e-324",
]


def _magnitude_value(tp, f, text):
    if tp is int:
        return text if "e" not in text else ("1" + "0" * 40 if float(text) > 1 else "0")
    if tp is tuple:
        template = f.default_factory()
        return json.dumps([[float(text)] * len(t) if isinstance(t, tuple) else float(text) for t in template])
    return text


@settings(max_examples=150, **HOSTILE)
@given(key=st.sampled_from(NUMERIC_KEYS), value=st.sampled_from(MAGNITUDES))
def test_generated_magnitudes_in_every_numeric_key(key, value, workdir, capsys):
    """150 generated (numeric key, tiny or huge magnitude) pairs, each a real 2-step run: exit 0, 2
    or 3 with no traceback, and no file written (run file, checkpoint, failure file) holds NaN or inf."""
    path, tp, f = key
    CASES["magnitudes"] += 1
    workdir = Path(tempfile.mkdtemp(dir=workdir))
    text = _magnitude_value(tp, f, value)
    scen = scenario_file(workdir, forces={**BASE["forces"], "plasma_filament": {}, "electric_field": {}})
    out = workdir / "out.h5"
    res = cli(capsys, "simulate", scen, "-o", out, "--progress", "none", f"--set={path}={text}")
    check_contract(res)
    bad = {p.name: non_finite_datasets(p) for p in workdir.glob("*.h5")}
    assert not any(bad.values()), f"non-finite values stored: {bad}"


@settings(max_examples=60, **HOSTILE)
@given(offset=st.floats(0.0, 1.0), bit=st.integers(0, 7))
def test_generated_bit_flips_in_a_checkpoint(offset, bit, workdir, capsys, real_run):
    """60 checkpoints with one bit flipped anywhere: resume exits 2 with a message (or 0 where the
    bit lies in unused bytes and the verified contents are unchanged), never a traceback, and a
    refused checkpoint leaves the run file untouched."""
    CASES["bit_flips"] += 1
    workdir = Path(tempfile.mkdtemp(dir=workdir))
    run = workdir / "run.h5"
    run.write_bytes(real_run["run_bytes"])
    raw = bytearray(real_run["checkpoint_bytes"])
    k = min(int(offset * len(raw)), len(raw) - 1)
    raw[k] ^= 1 << bit
    (workdir / "run.checkpoint.h5").write_bytes(bytes(raw))
    res = cli(capsys, "simulate", "--resume", run, "--progress", "none", "--t-end=0.004")
    check_contract(res, allowed=(0, 2))
    if res.code == 2:
        assert run.read_bytes() == real_run["run_bytes"]


@settings(max_examples=20, **HOSTILE)
@given(how=st.sampled_from(["copied", "moved", "foreign", "renamed"]), via=st.sampled_from(["run", "checkpoint"]))
def test_generated_moved_folders_and_foreign_checkpoints(how, via, workdir, capsys, real_run):
    """20 runs whose folder was copied, moved or renamed, or whose checkpoint comes from another
    run: a resume continues the files it was given (and nothing outside their folder), or refuses
    a foreign checkpoint with exit 2 naming both files."""
    CASES["moved_folders"] += 1
    workdir = Path(tempfile.mkdtemp(dir=workdir))  # one folder per generated case
    a = workdir / "a"
    shutil.copytree(real_run["dir"], a)
    outside = tree(real_run["dir"])
    if how == "foreign":
        res = cli(capsys, "simulate", a / "hostile.toml", "-o", a / "other.h5", "--progress", "none")
        check_contract(res, allowed=(0,))
        shutil.copy(a / "other.checkpoint.h5", a / "run.checkpoint.h5")
        target = a
    elif how == "renamed":
        target = workdir / "b"
        a.rename(target)
    else:
        target = workdir / "b"
        (shutil.copytree if how == "copied" else shutil.move)(a, target)
    name = "run.h5" if via == "run" else "run.checkpoint.h5"
    before = tree(target)
    res = cli(capsys, "simulate", "--resume", target / name, "--progress", "none", "--t-end=0.004")
    if how == "foreign" and via == "run":
        check_contract(res, allowed=(2,))
        assert "another run" in res.err and str(target / "run.h5") in res.err
        assert tree(target) == before
    elif how == "foreign":  # the checkpoint names its own run file beside it (other.h5) and continues that
        check_contract(res, allowed=(0,))
        assert tree(target)["run.h5"] == before["run.h5"]
    else:
        check_contract(res, allowed=(0,))
        assert sorted(tree(target)) == sorted(before)  # no file created, only these two changed
    assert tree(real_run["dir"]) == outside
    if how == "copied":
        assert tree(a) == outside


@pytest.mark.parametrize("kind", ["snapshot", "density", "timeline"])
@pytest.mark.parametrize("how", ["same_path", "hard_link", "symlink"])
def test_plot_onto_its_input(kind, how, workdir, capsys, real_run):
    """``plot RUN -o RUN --force`` (also through a link): exit 2, the run file intact."""
    pytest.importorskip("matplotlib")
    run = workdir / "run.h5"
    run.write_bytes(real_run["run_bytes"])
    target = run
    if how == "hard_link":
        target = workdir / "link.png"
        os.link(run, target)
    elif how == "symlink":
        target = workdir / "sym.png"
        target.symlink_to(run)
    res = cli(capsys, "plot", run, "--kind", kind, "-o", target, "--force")
    check_contract(res, allowed=(2,))
    assert run.read_bytes() == real_run["run_bytes"]
