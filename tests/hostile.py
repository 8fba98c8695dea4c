"""Helpers of the hostile-input tests (tests/validation/test_hostile.py, the property tests, and
tests/validation/test_hostile_bugs.py, the bugs they found, pinned): the in-process command line and its
contract, TOML writing, the walk over the scenario schema, the hypothesis strategies that
generate scenario files and hostile HDF5 files. The fixtures both modules use, ``real_run`` and
``workdir``, are in tests/conftest.py.
"""

from __future__ import annotations

import copy
import dataclasses
import math
import os
import re
import shutil
import tempfile
import tomllib
import traceback
import typing
from collections import Counter
from pathlib import Path

import h5py
import numpy as np
from hypothesis import HealthCheck, assume, event
from hypothesis import strategies as st
from hypothesis.configuration import set_hypothesis_home_dir

from selfas_graph.cli.main import main
from selfas_graph.io.checkpoint import FORMAT as CHECKPOINT_FORMAT
from selfas_graph.model import params as P

# --------------------------------------------------------------------------- settings and helpers

#: hypothesis keeps caches (unicode tables, constants) in a .hypothesis folder of the working
#: directory even without an example database: keep them out of the repository
set_hypothesis_home_dir(Path(tempfile.gettempdir()) / "selfas_graph_hypothesis")

#: derandomized (same cases on every machine), no deadline (the first real run compiles
#: kernels), no example database (nothing is written into the repository)
HOSTILE = dict(
    derandomize=True,
    deadline=None,
    database=None,
    print_blob=False,
    suppress_health_check=[
        HealthCheck.function_scoped_fixture,
        HealthCheck.too_slow,
        HealthCheck.filter_too_much,
        HealthCheck.data_too_large,
    ],
)

#: generated cases that ran, per test (printed at the end of the module)
CASES = Counter()

BASE = {
    "scenario": {"name": "hostile", "seed": 7},
    "rods": {"count": 4},
    "placement": {"box": [[-1.5, 1.5], [-1.5, 1.5], [-1.0, 1.0]]},
    "forces": {
        "tip_magnetic": {},
        "tip_brake": {},
        "ambient_brake": {},
        "uniform_field": {},
        "yukawa": {},
        "electrodes": {"gap": 2.0},
        "current_field": {},
        "current_lorentz": {},
    },
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
        assert re.search(r"^selfas-graph( \w+)?: error: \S", res.err, re.M), (
            f"exit 2 without a message naming the problem; stderr:\n{res.err[-2000:]}"
        )
    if res.code == 3:
        assert "numerical failure" in res.err, res.err[-2000:]


def tree(folder: Path) -> dict:
    """Every file under ``folder`` (relative path -> bytes; directories -> None; a symbolic link ->
    ("link", its target), so a link changed or replaced counts as a change)."""
    out = {}
    for p in sorted(folder.rglob("*")):
        key = str(p.relative_to(folder))
        out[key] = ("link", os.readlink(p)) if p.is_symlink() else None if p.is_dir() else p.read_bytes()
    return out


#: float datasets where NaN may mean "none": none since 0.4 (a floating tip's potential is flagged in
#: graph/floating, an open circuit's effective resistance has no row), so every float dataset is checked
NAN_MEANS_NONE: set = set()


def non_finite_datasets(path: Path) -> list:
    """Float datasets of an HDF5 file holding NaN or inf (but those of :data:`NAN_MEANS_NONE`)."""
    bad = []
    with h5py.File(path, "r") as f:
        f.visititems(
            lambda n, o: (
                bad.append(n)
                if isinstance(o, h5py.Dataset)
                and o.dtype.kind == "f"
                and n not in NAN_MEANS_NONE
                and not np.isfinite(o[()]).all()
                else None
            )
        )
    return bad


def skip_known(bug):
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


def scenario_file(d: Path, **sections) -> Path:
    """``d``/s.toml: BASE with the given tables updated."""
    raw = copy.deepcopy(BASE)
    for section, values in sections.items():
        raw.setdefault(section, {}).update(values)
    p = d / "s.toml"
    p.write_text(to_toml(raw))
    return p


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

SPECIAL_FLOATS = [
    0.0,
    -0.0,
    -1.0,
    0.5,
    2.0,
    1e-3,
    1e-300,
    5e-324,
    1e300,
    -1e300,
    1.7976931348623157e308,
    math.nan,
    math.inf,
    -math.inf,
]
GIANT_INTS = [2**31, 2**53 + 1, 2**63 - 1, -(2**63), 2**64, 10**30]

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


typed_set = st.sampled_from(sorted(LEAF_FIELDS)).flatmap(lambda p: typed_values(p).map(lambda v, p=p: ("set", p, v)))
mutations = st.lists(
    st.one_of(
        typed_set, typed_set, st.tuples(st.just("set"), paths, hostile_values), st.tuples(st.just("delete"), paths)
    ),
    min_size=1,
    max_size=3,
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
    how = draw(
        st.sampled_from(
            ["toml"] * 8
            + ["truncated", "junk", "non_utf8", "empty", "nul", "bom", "duplicate_table", "missing_sections", "deep"]
        )
    )
    if how == "truncated":
        data = data[: draw(st.integers(0, max(0, len(data) - 1)))]
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


# --------------------------------------------------------------------------- inputs left out


def _get(raw, *path, default=None):
    node = raw
    for k in path:
        if not isinstance(node, dict) or k not in node:
            return default
        node = node[k]
    return node


def _is_num(v):
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def known_bug_scenario(raw, real=False):
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


def nameless(path_text) -> bool:
    """A non-empty path whose last component is empty ('.', '/', 'a/..' is fine): RUN.checkpoint.h5 cannot be
    named after it. (An empty -o or output.file means 'the default name'.)"""
    return isinstance(path_text, str) and path_text != "" and Path(path_text).name == ""


# --------------------------------------------------------------------------- hostile files for topology, plot, resume

RUN_PATHS = [
    "h5md",
    "h5md/creator",
    "parameters",
    "parameters/selfas_graph",
    "particles",
    "particles/tips",
    "particles/tips/position",
    "particles/tips/position/value",
    "particles/tips/position/step",
    "particles/tips/position/time",
    "particles/tips/velocity/value",
    "particles/tips/charge",
    "particles/rods/charge",
    "observables",
    "observables/energy_balance/value",
    "observables/bond_error_per_step/step",
    "observables/bond_error_per_step/value",
    "events",
    "graph",
    "graph/step",
    "graph/time",
    "graph/role",
    "graph/current",
    "graph/tip_contacts_count",
    "snapshot",
    "snapshot/position",
    "meta",
]
h5_names = st.one_of(
    st.sampled_from(RUN_PATHS),
    st.lists(st.text(st.characters(categories=("L", "N")), min_size=1, max_size=5), min_size=1, max_size=3).map(
        "/".join
    ),
)
h5_items = st.tuples(
    h5_names,
    st.sampled_from(["group", "dataset"]),
    st.lists(st.integers(0, 4), max_size=3),
    st.sampled_from(["<f8", "<i8", "i1", "S4"]),
)
h5_attrs = st.dictionaries(
    st.sampled_from(["format", "parameters_json", "scenario_text", "status", "overrides", "run_file", "x"]),
    st.one_of(
        st.sampled_from([CHECKPOINT_FORMAT, "{}", "[]", "not json", "", "nan"]),
        st.integers(-3, 3),
        st.floats(allow_nan=True),
    ),
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
        path.write_bytes(template[: min(k, len(template) - 1)])
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


def rplus_open_changes(path: Path) -> bool:
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


def has_items(spec, *names):
    return spec[0] == "foreign" and any(item[0] in names for item in spec[1])


GRAPH_PATHS = [p for p in RUN_PATHS if p.startswith("graph")]


def has_run_markers(spec):
    """A foreign file with the two paths by which RunFile recognises a run."""
    return has_items(spec, "parameters/selfas_graph") and has_items(spec, "particles/tips/position/value")
