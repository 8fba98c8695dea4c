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

Disk-full, quota and kill cases run in subprocesses in ``tests/test_reliability.py`` (an I/O
failure may leave HDF5 in a state that only a process exit ends).

The number of cases that actually ran is printed at the end of the module (``hostile input:
N generated cases``); it is at most the total above.

The 26 bugs these tests found (tracebacks on absurd values, damaged files on resume and
output-name mistakes) are fixed; each is pinned by a ``test_bug_*`` test at the end of the
module with its input and the expected behaviour. A new bug is written the same way, first
marked ``xfail(strict=True)`` until it is fixed. The property tests leave out only inputs
that are slow rather than wrong (``_known_bug_scenario``: more than 500 rods to place).
"""
from __future__ import annotations

import copy
import dataclasses
import json
import math
import os
import re
import shutil
import stat
import tempfile
import tomllib
import traceback
import typing
from collections import Counter
from pathlib import Path

import h5py
import numpy as np
import pytest
from hypothesis import HealthCheck, assume, event, given, note, settings
from hypothesis import strategies as st
from hypothesis.configuration import set_hypothesis_home_dir

from selfas_graph import RunFile
from selfas_graph.cli.main import main
from selfas_graph.io.checkpoint import FORMAT as CHECKPOINT_FORMAT
from selfas_graph.io.scenario import _apply_override  # to know what a --set list makes of the scenario
from selfas_graph.model import params as P

# --------------------------------------------------------------------------- settings and helpers

#: hypothesis keeps caches (unicode tables, constants) in a .hypothesis folder of the working
#: directory even without an example database: keep them out of the repository
set_hypothesis_home_dir(Path(tempfile.gettempdir()) / "selfas_graph_hypothesis")

#: derandomized (same cases on every machine), no deadline (the first real run compiles
#: kernels), no example database (nothing is written into the repository)
HOSTILE = dict(derandomize=True, deadline=None, database=None, print_blob=False,
               suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow,
                                      HealthCheck.filter_too_much, HealthCheck.data_too_large])

#: generated cases that ran, per test (printed at the end of the module)
CASES = Counter()

BASE = {
    "scenario": {"name": "hostile", "seed": 7},
    "rods": {"count": 4},
    "placement": {"box": [[-1.5, 1.5], [-1.5, 1.5], [-1.0, 1.0]]},
    "forces": {"tip_magnetic": {}, "tip_brake": {}, "ambient_brake": {}, "uniform_field": {}, "yukawa": {},
               "electrodes": {"gap": 2.0}, "current_field": {}, "current_lorentz": {}},
    "circuit": {"delta_J0": 2.0},
    "integrator": {"dt": 1e-3},
    "run": {"t_end": 0.002},
    "output": {"interval": 0.001, "checkpoint_interval": 0},
}


class Result(typing.NamedTuple):
    code: int
    out: str
    err: str


def cli(capsys, *argv) -> Result:
    """Run ``selfas-graph ARGV`` in-process as the installed command would.

    argparse's usage errors (SystemExit) become their exit code; any other exception becomes
    what the console script would show: a traceback on stderr and exit code 1.
    """
    capsys.readouterr()
    try:
        code = main([str(a) for a in argv])
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
    except KeyboardInterrupt:  # pragma: no cover - the user's own Ctrl-C
        raise
    except BaseException as exc:  # noqa: BLE001 - MemoryError, RecursionError, ... are all contract breaches
        out, err = capsys.readouterr()
        return Result(1, out, err + "".join(traceback.format_exception(exc)))
    out, err = capsys.readouterr()
    return Result(code, out, err)


def check_contract(res: Result, allowed=(0, 2, 3)):
    """Exit code in ``allowed``; no traceback; a usage error comes with an error line."""
    try:
        event(f"exit {res.code}")
    except Exception:  # noqa: BLE001 - outside a hypothesis test (the xfail tests)
        pass
    assert res.code in allowed, f"exit code {res.code}, expected one of {allowed}; stderr:\n{res.err[-4000:]}"
    assert "Traceback" not in res.err, res.err[-4000:]
    if res.code == 2:
        assert re.search(r"^selfas-graph( \w+)?: error: \S", res.err, re.M), \
            f"exit 2 without a message naming the problem; stderr:\n{res.err[-2000:]}"
    if res.code == 3:
        assert "numerical failure" in res.err, res.err[-2000:]


def tree(folder: Path) -> dict:
    """Every file under ``folder`` (relative path -> bytes; directories -> None)."""
    out = {}
    for p in sorted(folder.rglob("*")):
        out[str(p.relative_to(folder))] = None if p.is_dir() else p.read_bytes()
    return out


def _skip_known(bug):
    """Leave out an input that hits a documented bug (its xfail test covers it)."""
    if bug:
        event(f"left out: {bug}")
    assume(bug is None)


def example_dir(root: Path) -> Path:
    return Path(tempfile.mkdtemp(dir=root))


# --------------------------------------------------------------------------- TOML writing

def toml_str(s: str) -> str:
    out = ['"']
    for ch in s:
        if ch == '"':
            out.append('\\"')
        elif ch == "\\":
            out.append("\\\\")
        elif ord(ch) < 0x20 or ord(ch) == 0x7F:
            out.append(f"\\u{ord(ch):04x}")
        else:
            out.append(ch)
    out.append('"')
    return "".join(out)


def toml_key(k: str) -> str:
    return k if re.fullmatch(r"[A-Za-z0-9_-]+", k) else toml_str(k)


def toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return toml_str(v)
    if isinstance(v, list):
        return "[" + ", ".join(toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{toml_key(k)} = {toml_value(x)}" for k, x in v.items()) + "}"
    raise TypeError(v)


def to_toml(raw: dict) -> str:
    """A TOML document: top-level values first, then one ``[section]`` per table (inline below)."""
    lines = [f"{toml_key(k)} = {toml_value(v)}" for k, v in raw.items() if not isinstance(v, dict)]
    for k, v in raw.items():
        if isinstance(v, dict):
            lines.append(f"\n[{toml_key(k)}]")
            lines += [f"{toml_key(kk)} = {toml_value(vv)}" for kk, vv in v.items()]
    return "\n".join(lines) + "\n"


BASE_TEXT = to_toml(BASE)
assert tomllib.loads(BASE_TEXT) == BASE


def parse(data: bytes):
    """The dict the loader would see, or None if the bytes are not UTF-8 TOML."""
    try:
        return tomllib.loads(data.decode("utf-8"))
    except (UnicodeDecodeError, tomllib.TOMLDecodeError):
        return None


# --------------------------------------------------------------------------- schema paths

def _leaf_fields(cls, prefix=()):
    """{path: (type, field)} of every schema key, tables included (optional tables as their dataclass)."""
    hints = typing.get_type_hints(cls)
    out = {}
    for f in dataclasses.fields(cls):
        tp = hints[f.name]
        if typing.get_origin(tp) is typing.Union:
            tp = [a for a in typing.get_args(tp) if a is not type(None)][0]
        out[prefix + (f.name,)] = (tp, f)
        if dataclasses.is_dataclass(tp):
            out.update(_leaf_fields(tp, prefix + (f.name,)))
    return out


#: every key path of the scenario schema -> (type, dataclass field); the tables; every key path
LEAF_FIELDS = _leaf_fields(P.Parameters)
SECTIONS = [()] + [p for p, (tp, _) in LEAF_FIELDS.items() if dataclasses.is_dataclass(tp)]
LEAVES = list(LEAF_FIELDS)

# --------------------------------------------------------------------------- strategies

SPECIAL_FLOATS = [0.0, -0.0, -1.0, 0.5, 2.0, 1e-3, 1e-300, 5e-324, 1e300, -1e300, 1.7976931348623157e308,
                  math.nan, math.inf, -math.inf]
GIANT_INTS = [2 ** 31, 2 ** 53 + 1, 2 ** 63 - 1, -(2 ** 63), 2 ** 64, 10 ** 30]

hostile_floats = st.one_of(st.sampled_from(SPECIAL_FLOATS), st.floats(allow_nan=True, allow_infinity=True))
hostile_ints = st.one_of(st.integers(-10, 50), st.sampled_from(GIANT_INTS))
hostile_text = st.one_of(
    st.sampled_from(["", "exact", "paper", "split", "explicit", "uniform", "magnetic", "nan", "1e-3", "true", "[]"]),
    st.text(st.characters(exclude_categories=("Cs",)), max_size=10),
)
scalars = st.one_of(hostile_floats, hostile_ints, st.booleans(), hostile_text)
key_names = st.one_of(
    st.sampled_from(["bogus", "Count", "dt ", "t-end", "yukwa", "gap", "value", "x.y", "", "ünï"]),
    st.text(st.characters(exclude_categories=("Cs",)), min_size=1, max_size=6),
)
hostile_values = st.recursive(
    scalars,
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(key_names, inner, max_size=3),
    max_leaves=8,
)
#: a key path: a key of the schema (leaf or table), or an unknown key in any table
paths = st.one_of(
    st.sampled_from(LEAVES),
    st.sampled_from(SECTIONS[1:]),
    st.tuples(st.sampled_from(SECTIONS), key_names).map(lambda t: t[0] + (t[1],)),
)


def _shaped(template, elements):
    if isinstance(template, (list, tuple)):
        return st.tuples(*[_shaped(t, elements) for t in template]).map(list)
    return elements


def typed_values(path):
    """Values of the type the schema expects at ``path``, at the edges of (and beyond) its range."""
    tp, f = LEAF_FIELDS[path]
    if dataclasses.is_dataclass(tp):
        return st.sampled_from([True, False, {}])
    if tp is bool:
        return st.booleans()
    if tp is str:
        choices = f.metadata.get("choices") or ()
        return st.one_of(st.sampled_from(list(choices) or ["x"]), hostile_text)
    if tp is int:
        return hostile_ints
    if tp is tuple:
        numbers = st.one_of(hostile_floats, st.floats(-10, 10), hostile_ints)
        return _shaped(f.default_factory(), numbers)
    return st.one_of(hostile_floats, hostile_ints, st.floats(0, 10), st.floats(1e-12, 1e-3))


typed_set = st.sampled_from(sorted(LEAF_FIELDS)).flatmap(
    lambda p: typed_values(p).map(lambda v, p=p: ("set", p, v)))
mutations = st.lists(
    st.one_of(typed_set, typed_set, st.tuples(st.just("set"), paths, hostile_values), st.tuples(st.just("delete"), paths)),
    min_size=1, max_size=3,
)


def mutate(raw: dict, ops) -> dict:
    raw = copy.deepcopy(raw)
    for op in ops:
        path = op[1]
        if not path:
            continue
        node = raw
        for name in path[:-1]:
            if op[0] == "delete" and not isinstance(node.get(name), dict):
                break
            if not isinstance(node.get(name), dict):
                node[name] = {}
            node = node[name]
        else:
            if op[0] == "set":
                node[path[-1]] = op[2]
            else:
                node.pop(path[-1], None)
    return raw


@st.composite
def scenario_files(draw):
    """(how, bytes): a mutated valid scenario, or a damaged version of one, or junk."""
    raw = mutate(BASE, draw(mutations))
    text = to_toml(raw)
    data = text.encode("utf-8")
    how = draw(st.sampled_from(["toml"] * 8 + ["truncated", "junk", "non_utf8", "empty", "nul", "bom",
                                              "duplicate_table", "missing_sections", "deep"]))
    if how == "truncated":
        data = data[:draw(st.integers(0, max(0, len(data) - 1)))]
    elif how == "junk":
        data = draw(st.binary(max_size=300))
    elif how == "non_utf8":
        k = draw(st.integers(0, len(data)))
        data = data[:k] + draw(st.sampled_from([b"\xff", b"\xfe\xff", b"\xc3", b"\xed\xa0\x80", b"\x80abc"])) + data[k:]
    elif how == "empty":
        data = draw(st.sampled_from([b"", b"\n", b"   \n\t\n", b"# only a comment\n"]))
    elif how == "nul":
        k = draw(st.integers(0, len(data)))
        data = data[:k] + b"\x00" + data[k:]
    elif how == "bom":
        data = b"\xef\xbb\xbf" + data
    elif how == "duplicate_table":
        data = data + b"\n[rods]\ncount = 5\n"
    elif how == "deep":  # nested arrays / inline tables, at depths tomllib still parses (see the xfail test)
        depth = draw(st.integers(1, 100))
        value = draw(st.sampled_from([("[" * depth, "]" * depth), ("{a = " * depth + "1", "}" * depth)]))
        key = draw(st.sampled_from(["count", "dt", "box", "bogus"]))
        data = data + f"\n[deep]\n{key} = {value[0]}{value[1]}\n".encode()
        if draw(st.booleans()):
            data = (value[0] + value[1]).join(["x = ", "\n"]).encode() + data
    elif how == "missing_sections":
        keep = draw(st.lists(st.sampled_from(sorted(BASE)), unique=True, max_size=len(BASE)))
        data = to_toml({k: v for k, v in raw.items() if k in keep}).encode()
    return how, data


# --------------------------------------------------------------------------- known bugs (see the xfail tests)

def _mag(v):
    try:
        return abs(float(v))
    except OverflowError:
        return math.inf


def _numbers(x):
    if isinstance(x, bool):
        return
    if isinstance(x, (int, float)):
        yield x
    elif isinstance(x, list):
        for v in x:
            yield from _numbers(v)
    elif isinstance(x, dict):
        for v in x.values():
            yield from _numbers(v)


def _get(raw, *path, default=None):
    node = raw
    for k in path:
        if not isinstance(node, dict) or k not in node:
            return default
        node = node[k]
    return node


def _is_num(v):
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _finite_pos(v, default):
    if v is None:
        return default
    if _is_num(v) and math.isfinite(_mag(v)) and v > 0:
        return float(v)
    return None


def _known_bug_scenario(raw, real=False):
    """Why a generated scenario is left out, or None.

    Every bug this once listed is fixed and pinned by a test_bug_* test. What remains is
    cost, not a bug: more than 500 rods that pass the packing check are placed one by one
    even by --dry-run, which for up to 10^7 rods takes minutes.
    """
    if raw is None:
        return None
    count = _get(raw, "rods", "count", default=300)
    if _is_num(count) and count > 500:
        return "slow: placing more than 500 rods"
    return None


def _nameless(path_text) -> bool:
    """A non-empty path whose last component is empty ('.', '/', 'a/..' is fine): RUN.checkpoint.h5 cannot be
    named after it. (An empty -o or output.file means 'the default name'.)"""
    return isinstance(path_text, str) and path_text != "" and Path(path_text).name == ""


def _known_bug_output_file(raw):
    """Kept for the generators' call sites: every output.file bug it listed is fixed (test_bug_* pin them)."""
    return None


# --------------------------------------------------------------------------- fixtures

@pytest.fixture(scope="module", autouse=True)
def _report_cases(request):
    yield
    total = sum(CASES.values())
    line = "hostile input: %d generated cases (%s)" % (
        total, ", ".join(f"{k} {v}" for k, v in sorted(CASES.items())))
    reporter = request.config.pluginmanager.get_plugin("terminalreporter")
    if reporter is not None:
        reporter.write_line("\n" + line)
    else:  # pragma: no cover
        print(line)


@pytest.fixture(scope="module")
def real_run(tmp_path_factory):
    """One small real run (4 rods, 2 steps, 3 frames, graph data) and its checkpoint, written once."""
    d = tmp_path_factory.mktemp("real_run")
    scen = d / "hostile.toml"
    scen.write_text(BASE_TEXT)
    run = d / "run.h5"
    try:
        code = main(["simulate", str(scen), "-o", str(run), "--progress", "none"])
    except SystemExit as exc:  # pragma: no cover
        code = exc.code
    assert code == 0
    ckpt = d / "run.checkpoint.h5"
    assert run.exists() and ckpt.exists()
    return RealRun(dir=d, scenario=scen, run=run, checkpoint=ckpt,
                   run_bytes=run.read_bytes(), checkpoint_bytes=ckpt.read_bytes())


class RealRun(dict):
    """The module's real run (a dict with a short repr: failure reports stay readable)."""

    def __repr__(self):
        return f"RealRun({self['run']})"


@pytest.fixture
def workdir(tmp_path, monkeypatch):
    """A scratch folder that is also the working directory (so no stray file lands in the repo)."""
    monkeypatch.chdir(tmp_path)
    return tmp_path


# --------------------------------------------------------------------------- generated scenario files

def _plan(out: str) -> dict | None:
    """The JSON plan printed by ``--dry-run``."""
    k = out.find("\n{")
    if k < 0:
        return None
    try:
        return json.loads(out[k + 1:])
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
    bug = _known_bug_scenario(raw) or (None if with_o else _known_bug_output_file(raw))
    note(f"how={how} bug={bug}\n{data[:3000]!r}")
    event(f"file: {how}")
    _skip_known(bug)
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
    bug = _known_bug_scenario(raw, real=True)
    note(f"how={how} bug={bug}\n{data[:3000]!r}")
    event(f"file: {how}")
    _skip_known(bug)
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
    st.sampled_from(["", ".", "a..b", " rods.count ", "rods.count.x", "forces.yukawa.x.y", "output.file.z", "rods.",
                     ".rods", "run.t_end=1", "scenario", "forces"]),
    st.lists(key_names, min_size=1, max_size=3).map(".".join),
)
set_values = st.one_of(
    hostile_values.map(toml_value),
    st.text(st.characters(exclude_categories=("Cs",)), max_size=12),
    st.sampled_from(["", "=", "[", "{", "nan", "-inf", "1e999", "0x10", "1_000", "true", "\"unterminated", "{a = 1}",
                     "[" * 60 + "]" * 60, "1\nrods = 3", "'literal'", "2024-01-01", "[[0, 1], [0, 1], [0, 1]]"]),
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
    bug = _known_bug_scenario(_effective(items))
    note(f"bug={bug}")
    _skip_known(bug)
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
    bug = _known_bug_scenario(_effective(t_end=t), real=True) if t is not None else None
    note(f"bug={bug}")
    _skip_known(bug)
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
    st.tuples(st.just("-o"), st.sampled_from(["out.h5", "/", ".", "", "sub/out.h5", "SCEN", "adir", "out.checkpoint.h5",
                                               "x", "adir/", "-", "out.h5/"])),
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
@given(positional=st.sampled_from([None, "SCEN", "missing.toml", ".", "", "-", "adir", "SCEN SCEN"]),
       options=st.lists(simulate_options, max_size=5), order=st.randoms(use_true_random=False))
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
    bug = "test_bug_output_path_without_a_name" if _nameless(out) or (resume and _nameless(resume)) else None
    note(f"argv={argv} bug={bug}")
    _skip_known(bug)
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
    lambda s: s not in (".", ".."))
output_cases = st.one_of(
    st.tuples(st.just("missing_folder"), st.lists(name_parts, min_size=1, max_size=3)),
    st.tuples(st.just("file_as_folder"), name_parts),
    st.tuples(st.just("existing"), st.binary(max_size=200)),
    st.tuples(st.just("existing_run")),
    st.tuples(st.just("directory"), st.booleans()),
    st.tuples(st.just("scenario_itself")),
    st.tuples(st.just("output_file_key"), st.one_of(
        st.sampled_from(["", ".", "..", "a", "adir", "s.toml", "a\x00b.h5", " ", "x.h5 ", "\u00e9.h5"]),
        st.text(st.characters(exclude_categories=("Cs",), exclude_characters="/"), max_size=8))),
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
        bug = _known_bug_output_file({"output": {"file": name}})
        note(f"output.file={name!r} bug={bug}")
        _skip_known(bug)
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


# --------------------------------------------------------------------------- hostile files for topology, plot, resume

RUN_PATHS = ["h5md", "h5md/creator", "parameters", "parameters/selfas_graph", "particles", "particles/tips",
             "particles/tips/position", "particles/tips/position/value", "particles/tips/position/step",
             "particles/tips/position/time", "particles/tips/velocity/value", "particles/tips/charge",
             "particles/rods/charge", "observables", "observables/energy_balance/value",
             "observables/bond_error_per_step/step", "observables/bond_error_per_step/value", "events",
             "graph", "graph/step", "graph/time", "graph/role", "graph/current", "graph/tip_contacts_count",
             "snapshot", "snapshot/position", "meta"]
h5_names = st.one_of(st.sampled_from(RUN_PATHS),
                     st.lists(st.text(st.characters(categories=("L", "N")), min_size=1, max_size=5),
                              min_size=1, max_size=3).map("/".join))
h5_items = st.tuples(
    h5_names,
    st.sampled_from(["group", "dataset"]),
    st.lists(st.integers(0, 4), max_size=3),
    st.sampled_from(["<f8", "<i8", "i1", "S4"]),
)
h5_attrs = st.dictionaries(
    st.sampled_from(["format", "parameters_json", "scenario_text", "status", "overrides", "run_file", "x"]),
    st.one_of(st.sampled_from([CHECKPOINT_FORMAT, "{}", "[]", "not json", "", "nan"]), st.integers(-3, 3),
              st.floats(allow_nan=True)),
    max_size=3,
)
hostile_files = st.one_of(
    st.tuples(st.just("truncated"), st.one_of(st.integers(0, 4096), st.floats(0, 1, exclude_max=True))),
    st.tuples(st.just("junk"), st.binary(max_size=2048)),
    st.tuples(st.just("hdf5_signature_junk"), st.binary(max_size=2048)),
    st.tuples(st.just("empty")),
    st.tuples(st.just("directory")),
    st.tuples(st.just("text")),
    st.tuples(st.just("foreign"), st.lists(h5_items, max_size=8), h5_attrs, h5_attrs),
)


def make_hostile_file(spec, path: Path, template: bytes) -> Path:
    kind = spec[0]
    if kind == "truncated":
        cut = spec[1]
        k = cut if isinstance(cut, int) else int(cut * len(template))
        path.write_bytes(template[:min(k, len(template) - 1)])
    elif kind == "junk":
        path.write_bytes(spec[1])
    elif kind == "hdf5_signature_junk":
        path.write_bytes(b"\x89HDF\r\n\x1a\n" + spec[1])
    elif kind == "empty":
        path.write_bytes(b"")
    elif kind == "directory":
        path.mkdir()
        (path / "inside.h5").write_bytes(b"x")
    elif kind == "text":
        path.write_text(BASE_TEXT)
    else:
        _, items, root_attrs, meta_attrs = spec
        with h5py.File(path, "w") as f:
            for key, value in root_attrs.items():
                f.attrs[key] = value
            for name, what, shape, dtype in items:
                try:
                    if what == "group":
                        f.require_group(name)
                    else:
                        f.create_dataset(name, data=np.zeros(tuple(shape), dtype=dtype))
                except (ValueError, TypeError, KeyError):
                    pass  # the name clashes with an item made before: keep the first
            for group in ("parameters/selfas_graph", "meta"):
                if group in f and isinstance(f[group], h5py.Group):
                    for key, value in meta_attrs.items():
                        f[group].attrs[key] = value
    return path


def _rplus_open_changes(path: Path) -> bool:
    """Whether merely opening a copy of the file with h5py in 'r+' mode and closing it changes its bytes
    (HDF5 creates a superblock in an empty file and rewrites cached root-group entries of some files)."""
    if not path.is_file():
        return False
    copy_ = path.with_name(path.name + ".probe")
    shutil.copyfile(path, copy_)
    try:
        h5py.File(copy_, "r+").close()
    except OSError:
        return False
    else:
        return copy_.read_bytes() != path.read_bytes()
    finally:
        copy_.unlink()


def snapshot_of(path: Path):
    return tree(path) if path.is_dir() else path.read_bytes()


def _has(spec, *names):
    return spec[0] == "foreign" and any(item[0] in names for item in spec[1])


GRAPH_PATHS = [p for p in RUN_PATHS if p.startswith("graph")]


def _has_run_markers(spec):
    """A foreign file with the two paths by which RunFile recognises a run."""
    return _has(spec, "parameters/selfas_graph") and _has(spec, "particles/tips/position/value")


@settings(max_examples=80, **HOSTILE)
@given(spec=hostile_files, json_out=st.booleans())
def test_hostile_files_to_topology(spec, json_out, workdir, capsys, real_run):
    """80 generated files given to ``topology`` (truncated copies of a real run, junk bytes with and
    without the HDF5 signature, empty file, a directory, a text file, foreign HDF5 files with random
    groups and datasets, some named like a run's): exit 2 with a message, no traceback, no stdout,
    the file byte-identical afterwards."""
    bug = ("test_bug_topology_foreign_graph" if _has_run_markers(spec) and _has(spec, *GRAPH_PATHS) else None)
    note(f"bug={bug}")
    _skip_known(bug)
    CASES["topology_files"] += 1
    d = example_dir(workdir)
    f = make_hostile_file(spec, d / "run.h5", real_run["run_bytes"])
    before = snapshot_of(f)
    res = cli(capsys, "topology", f, *(["--json"] if json_out else []))
    check_contract(res, allowed=(2,))
    assert res.out == ""
    assert snapshot_of(f) == before


@settings(max_examples=40, **HOSTILE)
@given(frame=st.one_of(st.none(), st.integers(-10, 10), st.sampled_from(GIANT_INTS)),
       time=st.one_of(st.none(), hostile_floats),
       events=st.one_of(st.none(), st.integers(-5, 5), st.sampled_from(GIANT_INTS)),
       json_out=st.booleans(), junk=st.sampled_from([None, "x", "1.5", ""]))
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
    bug = "test_bug_plot_foreign_file_with_run_layout" if _has_run_markers(spec) else None
    note(f"bug={bug}")
    _skip_known(bug)
    CASES["plot_files"] += 1
    d = example_dir(workdir)
    f = make_hostile_file(spec, d / "run.h5", real_run["run_bytes"])
    before = tree(d)
    res = cli(capsys, "plot", f, "--kind", kind, "-o", d / "fig.png", "--dpi", "20")
    check_contract(res, allowed=(2,))
    assert tree(d) == before


@settings(max_examples=15, **HOSTILE)
@given(kind=st.sampled_from(["snapshot", "density", "field", "flux", "timeline"]),
       r_max=st.one_of(st.none(), st.sampled_from([0.0, -1.0, math.nan, 1e-300, 0.5, 3.0, 1e6])),
       planes=st.one_of(st.none(), st.lists(st.floats(-1e6, 1e6), min_size=1, max_size=4)),
       bins=st.one_of(st.none(), st.integers(-3, 200)),
       n_phi=st.one_of(st.none(), st.integers(-3, 500)),
       z_mext=st.one_of(st.none(), st.sampled_from([0.0, math.nan, math.inf, -2.0, 1e-300, 10.0])),
       dpi=st.integers(10, 60), frame=st.one_of(st.none(), st.integers(-5, 5)))
def test_generated_plot_arguments(kind, r_max, planes, bins, n_phi, z_mext, dpi, frame, workdir, capsys, real_run):
    """15 generated option sets of ``plot`` on a real run (--r-max zero/negative/NaN/tiny/huge, finite
    --planes, --bins and --n-phi below 1 and up to hundreds, --z-mext zero/NaN/inf, frames in and out of
    range, dpi 10..60): exit 0 or 2, no traceback, a PNG only after exit 0, the run file unchanged.
    (Infinite --r-max, non-finite --planes and out-of-range --dpi are the test_bug_* tests below.)"""
    CASES["plot_args"] += 1
    d = example_dir(workdir)
    png = d / "fig.png"
    argv = ["plot", real_run["run"], "--kind", kind, "-o", png, f"--dpi={dpi}"]
    for opt, value in (("--r-max", r_max), ("--bins", bins), ("--n-phi", n_phi), ("--z-mext", z_mext),
                       ("--frame", frame)):
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
    bug = ("test_bug_checkpoint_with_missing_groups"
           if spec[0] == "foreign" and spec[2].get("format") == CHECKPOINT_FORMAT else None)
    note(f"bug={bug}")
    _skip_known(bug)
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
    if _rplus_open_changes(f):
        bug = "test_bug_failed_resume_rewrites_the_file"
    elif _has(spec, "particles/tips/position/step"):
        bug = "test_bug_resume_into_a_file_of_another_layout"
    note(f"bug={bug}")
    _skip_known(bug)
    CASES["resume_run_files"] += 1
    ckpt = d / "good.checkpoint.h5"
    ckpt.write_bytes(real_run["checkpoint_bytes"])
    before = tree(d)
    res = cli(capsys, "simulate", "--resume", ckpt, "-o", f, "--progress", "none",
              *([f"--t-end={t_end}"] if t_end else []))
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
MAGNITUDES = ["5e-324", "1e-310", "1e-300", "1e-31", "1e-30", "1e30", "1e31", "1e200", "1e308",
              "-1e30", "-1e308", "-5e-324"]


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
    or 3 with no traceback, and a run file, if written, holds no NaN or inf."""
    path, tp, f = key
    CASES["magnitudes"] += 1
    workdir = Path(tempfile.mkdtemp(dir=workdir))
    text = _magnitude_value(tp, f, value)
    scen = _scenario(workdir, forces={**BASE["forces"], "plasma_filament": {}, "electric_field": {}})
    out = workdir / "out.h5"
    res = cli(capsys, "simulate", scen, "-o", out, "--progress", "none", f"--set={path}={text}")
    check_contract(res)
    if res.code in (0, 3) and out.exists():
        allowed = {"graph/potential", "graph/conductor_potential", "observables/effective_resistance/value"}
        with h5py.File(out, "r") as h:
            bad = []
            h.visititems(lambda n, o: bad.append(n) if isinstance(o, h5py.Dataset) and o.dtype.kind == "f"
                         and n not in allowed and not np.isfinite(o[()]).all() else None)
        assert not bad, f"non-finite values stored in {bad}"


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


# =========================================================================== bugs found, now fixed

def _scenario(d: Path, **sections) -> Path:
    raw = copy.deepcopy(BASE)
    for section, values in sections.items():
        raw.setdefault(section, {}).update(values)
    p = d / "s.toml"
    p.write_text(to_toml(raw))
    return p


def _expect_usage_error(res: Result, *words):
    check_contract(res, allowed=(2,))
    for w in words:
        assert w in res.err


def test_bug_huge_placement_box(workdir, capsys):
    scen = _scenario(workdir, placement={"box": [[-1e200, 1e200], [-1.0, 1.0], [-1.0, 1.0]]})
    _expect_usage_error(cli(capsys, "simulate", scen, "--dry-run"), "placement.box")


def test_bug_tiny_placement_box(workdir, capsys):
    scen = _scenario(workdir, placement={"box": [[0.0, 1e-300], [0.0, 1e-300], [0.0, 1e-300]]})
    _expect_usage_error(cli(capsys, "simulate", scen, "--dry-run"), "placement.box")


def test_bug_huge_min_tip_distance(workdir, capsys):
    scen = _scenario(workdir, placement={"min_tip_distance": 1e300})
    _expect_usage_error(cli(capsys, "simulate", scen, "--dry-run"), "min_tip_distance")


@pytest.mark.parametrize("term", ["current_lorentz", "external_dipole"])
def test_bug_huge_quadrature_points(term, workdir, capsys):
    res = cli(capsys, "simulate", _scenario(workdir), "--dry-run",
              f"--set=forces.{term}.quadrature_points=9223372036854775807")
    _expect_usage_error(res, "quadrature_points")


@pytest.mark.parametrize("args", [["--set=integrator.dt=5e-324"], ["--t-end=1.7e308"],
                                  ["--set=integrator.dt=1e-10", "--set=output.interval=1e300"]])
def test_bug_step_count_overflow(args, workdir, capsys):
    check_contract(cli(capsys, "simulate", _scenario(workdir), "--dry-run", *args), allowed=(2,))


def test_bug_huge_rod_count(workdir, capsys):
    scen = _scenario(workdir, rods={"count": 10 ** 12}, placement={"min_tip_distance": 0.0})
    _expect_usage_error(cli(capsys, "simulate", scen, "--dry-run"), "rods.count")


def test_bug_seed_beyond_64_bits(workdir, capsys):
    out = workdir / "out.h5"
    res = cli(capsys, "simulate", _scenario(workdir, scenario={"seed": 2 ** 64}), "-o", out, "--progress", "none")
    check_contract(res, allowed=(0, 2))
    assert out.exists() == (res.code == 0)


def test_bug_huge_output_interval(workdir, capsys):
    out = workdir / "out.h5"
    res = cli(capsys, "simulate", _scenario(workdir, output={"interval": 1e300}), "-o", out, "--progress", "none")
    check_contract(res, allowed=(0, 2))
    assert out.exists() == (res.code == 0)


def test_bug_huge_neighbour_skin(workdir, capsys):
    res = cli(capsys, "simulate", _scenario(workdir, neighbours={"skin": 1e300}), "-o", workdir / "out.h5",
              "--progress", "none")
    check_contract(res)


@pytest.mark.parametrize("sections", [{"rods": {"tip_stiffness": 1e300}},
                                      {"forces": {"uniform_field": {"B": [1e300, 0.0, 0.0]}}}])
def test_bug_overflowing_forces(sections, workdir, capsys):
    raw = copy.deepcopy(BASE)
    for k, v in sections.items():
        raw[k].update(v)
    scen = workdir / "s.toml"
    scen.write_text(to_toml(raw))
    res = cli(capsys, "simulate", scen, "-o", workdir / "out.h5", "--progress", "none")
    check_contract(res, allowed=(2, 3))


def test_bug_resume_into_an_unrelated_run(workdir, capsys, real_run):
    other = workdir / "B.h5"
    res = cli(capsys, "simulate", real_run["scenario"], "-o", other, "--progress", "none",
              "--set=rods.count=6", "--t-end=0.005")
    assert res.code == 0
    before = other.read_bytes()
    ckpt = workdir / "A.checkpoint.h5"
    ckpt.write_bytes(real_run["checkpoint_bytes"])
    res = cli(capsys, "simulate", "--resume", ckpt, "-o", other, "--progress", "none", "--t-end=0.004")
    check_contract(res, allowed=(2,))
    assert other.read_bytes() == before


@pytest.mark.parametrize("content", ["empty", "foreign_non_ascii_group"])
def test_bug_failed_resume_rewrites_the_file(content, workdir, capsys, real_run):
    ckpt = workdir / "good.checkpoint.h5"
    ckpt.write_bytes(real_run["checkpoint_bytes"])
    target = workdir / "target.h5"
    if content == "empty":
        target.write_bytes(b"")
    else:
        with h5py.File(target, "w") as f:
            f.create_group("\u00e9t\u00e9")
    before = target.read_bytes()
    res = cli(capsys, "simulate", "--resume", ckpt, "-o", target, "--progress", "none")
    _expect_usage_error(res, "cannot resume")
    assert target.read_bytes() == before


def test_bug_resume_into_a_file_of_another_layout(workdir, capsys, real_run):
    ckpt = workdir / "good.checkpoint.h5"
    ckpt.write_bytes(real_run["checkpoint_bytes"])
    foreign = workdir / "foreign.h5"
    with h5py.File(foreign, "w") as f:
        f.create_group("particles/tips/position/step")
    before = foreign.read_bytes()
    res = cli(capsys, "simulate", "--resume", ckpt, "-o", foreign, "--progress", "none")
    check_contract(res, allowed=(2,))
    assert foreign.read_bytes() == before


@pytest.mark.parametrize("groups", [(), ("snapshot", "meta")])
def test_bug_checkpoint_with_missing_groups(groups, workdir, capsys):
    ckpt = workdir / "x.checkpoint.h5"
    with h5py.File(ckpt, "w") as f:
        f.attrs["format"] = CHECKPOINT_FORMAT
        for g in groups:
            f.create_group(g)
    _expect_usage_error(cli(capsys, "simulate", "--resume", ckpt), "cannot resume")


@pytest.mark.parametrize("layout", ["value_group", "value_only", "scalars"])
def test_bug_plot_foreign_file_with_run_layout(layout, workdir, capsys):
    path = workdir / "f.h5"
    with h5py.File(path, "w") as f:
        if layout == "value_group":
            f.create_group("parameters/selfas_graph")
            f.create_group("particles/tips/position/value")
        elif layout == "value_only":
            f.create_group("parameters/selfas_graph")
            f["particles/tips/position/value"] = np.zeros((2, 8, 3))
        else:
            f["parameters/selfas_graph"] = 1
            f["particles/tips/position/value"] = 1
    res = cli(capsys, "plot", path, "-o", workdir / "f.png")
    check_contract(res, allowed=(2,))


def test_bug_topology_foreign_graph(workdir, capsys):
    path = workdir / "f.h5"
    with h5py.File(path, "w") as f:
        f.create_group("parameters/selfas_graph")
        f["particles/tips/position/value"] = np.zeros((1, 8, 3))
        f["graph/step"] = np.zeros(1, dtype=np.int64)
    check_contract(cli(capsys, "topology", path), allowed=(2,))


@pytest.mark.parametrize("dpi", ["0", "-5", "1", "100000"])
def test_bug_plot_dpi(dpi, workdir, capsys, real_run):
    res = cli(capsys, "plot", real_run["run"], "-o", workdir / "f.png", f"--dpi={dpi}")
    _expect_usage_error(res, "--dpi")
    assert not (workdir / "f.png").exists()


@pytest.mark.parametrize("kind", ["density", "field", "flux"])
def test_bug_plot_infinite_r_max(kind, workdir, capsys, real_run):
    res = cli(capsys, "plot", real_run["run"], "--kind", kind, "-o", workdir / "f.png", "--r-max=inf")
    _expect_usage_error(res, "--r-max")


@pytest.mark.parametrize("kind", ["field", "flux"])
def test_bug_plot_huge_r_max_is_bounded(kind, workdir, capsys, real_run):
    """--r-max 1e9 set the default azimuthal sampling to ~2e11 points per radius (minutes or
    memory exhaustion); radii are bounded like every size-like option."""
    res = cli(capsys, "plot", real_run["run"], "--kind", kind, "-o", workdir / "f.png", "--r-max=1e9")
    _expect_usage_error(res, "at most 500 L")


@pytest.mark.parametrize("kind, plane", [("field", "nan"), ("flux", "inf")])
def test_bug_plot_nonfinite_planes(kind, plane, workdir, capsys, real_run):
    res = cli(capsys, "plot", real_run["run"], "--kind", kind, "-o", workdir / "f.png", "--planes", plane)
    _expect_usage_error(res, "--planes")


@pytest.mark.parametrize("data", ["truncated", "signature_junk"])
def test_bug_truncated_file_message_blames_file_locking(data, workdir, capsys, real_run):
    path = workdir / "run.h5"
    if data == "truncated":
        path.write_bytes(real_run["run_bytes"][:len(real_run["run_bytes"]) // 2])
    else:
        path.write_bytes(b"\x89HDF\r\n\x1a\n" + b"\xff" * 1024)  # HDF5: "bad superblock version number"
    res = cli(capsys, "topology", path)
    check_contract(res, allowed=(2,))
    assert "HDF5_USE_FILE_LOCKING" not in res.err and "still writing" not in res.err


@pytest.mark.parametrize("victim", ["other_file", "the_scenario"])
def test_bug_checkpoint_overwrites_an_existing_file(victim, workdir, capsys):
    if victim == "other_file":
        scen = _scenario(workdir)
        precious = workdir / "new.checkpoint.h5"
        precious.write_bytes(b"results of last week")
    else:
        precious = workdir / "new.checkpoint.h5"
        precious.write_text(BASE_TEXT)
        scen = precious
    before = precious.read_bytes()
    res = cli(capsys, "simulate", scen, "-o", workdir / "new.h5", "--progress", "none")
    check_contract(res, allowed=(0, 2))
    assert precious.read_bytes() == before


def test_bug_resume_t_end_before_the_checkpoint(workdir, capsys, real_run):
    run = workdir / "run.h5"
    run.write_bytes(real_run["run_bytes"])
    ckpt = workdir / "run.checkpoint.h5"
    ckpt.write_bytes(real_run["checkpoint_bytes"])
    res = cli(capsys, "simulate", "--resume", ckpt, "-o", run, "--t-end=0.001", "--progress", "none")
    _expect_usage_error(res, "t_end")
    assert run.read_bytes() == real_run["run_bytes"]


@pytest.mark.parametrize("rods", [{"electric_charge": {"distribution": "constant", "value": 0.0}},
                                  {"magnetic_charge": {"value": 0.0}}])
def test_bug_yukawa_with_zero_charges(rods, workdir, capsys):
    out = workdir / "out.h5"
    res = cli(capsys, "simulate", _scenario(workdir, rods=rods), "-o", out, "--progress", "none")
    check_contract(res, allowed=(0,))


@pytest.mark.parametrize("args", [["-o", ".", "--dry-run"], ["-o", "/", "--dry-run"], ["-o", "."],
                                  ["--set=output.file=\".\"", "--dry-run"], ["--resume", "."], ["--resume", "/"]])
def test_bug_output_path_without_a_name(args, workdir, capsys):
    scen = _scenario(workdir)
    argv = ["simulate", *([] if "--resume" in args else [scen]), *args]
    check_contract(cli(capsys, *argv), allowed=(2,))


def test_bug_output_file_with_a_nul_character(workdir, capsys):
    precious = workdir / "a"
    precious.write_bytes(b"results of last week")
    scen = workdir / "s.toml"
    scen.write_text(BASE_TEXT + 'file = "a\\u0000b.h5"\n')
    res = cli(capsys, "simulate", scen.name, "--progress", "none")
    check_contract(res, allowed=(2,))
    assert precious.read_bytes() == b"results of last week"


@pytest.mark.parametrize("where", ["file_array", "file_table", "set_value"])
def test_bug_deeply_nested_toml(where, workdir, capsys):
    depth = 5000
    scen = workdir / "s.toml"
    if where == "file_array":
        scen.write_text("x = " + "[" * depth + "]" * depth + "\n")
    elif where == "file_table":
        scen.write_text("x = " + "{a = " * depth + "1" + "}" * depth + "\n")
    else:
        scen.write_text(BASE_TEXT)
    extra = [f"--set=rods.count={'[' * depth}{']' * depth}"] if where == "set_value" else []
    check_contract(cli(capsys, "simulate", scen, "--dry-run", *extra), allowed=(2,))
