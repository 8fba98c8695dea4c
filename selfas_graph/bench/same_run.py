"""Check that two run files hold the same data, bit for bit.

Usage::

    selfas-graph compare RUN_A.h5 RUN_B.h5 [--ignore-attrs]

Walks both HDF5 files and compares every dataset (shape, dtype and bytes; NaN equals NaN
at the same place, since the bytes are compared) and, unless ``--ignore-attrs``, every
attribute except those that record the wall clock, the software or how the run was launched (``created``,
``version``, timings: see ``VOLATILE``); the ``--set`` overrides compare in any order (``ORDERLESS``). Prints the differences and exits 1 if there are
any, 0 if the files agree. Attributes that only describe what a dataset holds, which a later
version added (``DESCRIBING``; the words of ``derived_json``'s ``*_sum`` entries), are named
but not counted: a file of an earlier version compares equal to its twin of this one.

Use it to show that a change to the code keeps a run's results: run the same scenario
before and after the change (same thread count), then compare, e.g.::

    selfas-graph simulate scenarios/quick.toml -o /tmp/before.h5   # on the old commit
    selfas-graph simulate scenarios/quick.toml -o /tmp/after.h5    # on the new one
    selfas-graph compare /tmp/before.h5 /tmp/after.h5
"""

from __future__ import annotations

import argparse
import math
import struct
import sys

import h5py
import numpy as np

#: attribute names (any group) that differ between two runs of the same scene by design
VOLATILE = (
    "created",
    "creation_time",
    "date",
    "version",
    "program_version",
    "wall",
    "elapsed",
    "steps_per_second",
    "hostname",
    "host",
    "cpu",
    "run_file",
    "git",
    "command",
    "run_id",
    "commit",
    "resumed_with",
    "steps_done",  # the run loop's steps in the last segment: a resumed run and its uninterrupted twin differ
    "t_end_before",  # the end times a run was started with before a resume moved it: its history, not its data
    # how a run was launched, which its data do not depend on: MPI ranks and numba threads give the same run bit
    # for bit (docs/performance.md 'Several MPI ranks'), and the scene file may be read from another folder
    "mpi_ranks",
    "numba_threads",
    "scenario_path",
)  # run_id: a random identifier drawn for every run


#: attributes that only say what a dataset holds, added by a later version without changing a value (H5MD
#: 1.1's ``type`` and ``quantity`` of the charges, since 0.4.3): one file without them is an earlier version's
DESCRIBING = tuple(f"particles/{g}/charge@{a}" for g in ("tips", "rods") for a in ("type", "quantity"))
#: entries of the ``derived_json`` attribute that describe a setting in words (``*_sum``: how a sum is done)
DESCRIBING_SUFFIX = "_sum"


#: attributes holding a JSON list whose order is not part of the run: the ``--set`` overrides (an ensemble
#: seed and its ``simulate --set ...`` twin list them in another order; should the order matter, because a
#: key is set twice, the resolved parameters in ``parameters_json`` differ and are reported)
ORDERLESS = ("overrides",)


def _json_pair(a, b, kind):
    """Two attribute values read as JSON texts of ``kind`` (list or dict), or None when either is not one."""
    import json

    try:
        a, b = (json.loads(v.decode() if isinstance(v, bytes) else v) for v in (a, b))
    except (TypeError, ValueError, AttributeError, UnicodeDecodeError):
        return None
    return (a, b) if isinstance(a, kind) and isinstance(b, kind) else None


def _same_items(a, b) -> bool:
    """Whether two JSON texts of lists hold the same items, in any order."""
    import json

    pair = _json_pair(a, b, list)
    return pair is not None and sorted(map(json.dumps, pair[0])) == sorted(map(json.dumps, pair[1]))


def _volatile(name: str) -> bool:
    low = name.lower()
    return any(v in low for v in VOLATILE)


def _same_value(a, b) -> bool:
    a, b = np.asarray(a), np.asarray(b)
    if a.shape != b.shape or a.dtype != b.dtype:
        return False
    if a.dtype.kind == "O":
        return all(x == y for x, y in zip(a.ravel().tolist(), b.ravel().tolist()))
    return np.ascontiguousarray(a).tobytes() == np.ascontiguousarray(b).tobytes()


def _json_differences(a, b):
    """The entries in which two JSON texts of objects differ, as ``key.sub: A != B`` lines (None when either
    is not such a text)."""
    pair = _json_pair(a, b, dict)
    if pair is None:
        return None
    a, b = pair

    def flat(d, prefix=""):
        out = {}
        for k, v in d.items():
            out.update(flat(v, f"{prefix}{k}.") if isinstance(v, dict) and v else {f"{prefix}{k}": v})
        return out

    fa, fb = flat(a), flat(b)
    missing = "(absent)"
    lines = [
        (k, f"{k}: {fa.get(k, missing)!r} != {fb.get(k, missing)!r}")
        for k in sorted(set(fa) | set(fb))
        if not _same_leaf(fa.get(k, missing), fb.get(k, missing))
    ]
    if not lines:  # the texts differ (else this is not called) in nothing an entry shows: their order, spacing
        lines = [("", "the same entries, written differently (order or spacing of the JSON text)")]
    return lines


def _same_leaf(x, y) -> bool:
    """Two JSON values the same to the bit: of one type (1 is not 1.0, nor true), -0.0 not 0.0, NaN the
    same as NaN; lists entry by entry."""
    if type(x) is not type(y):
        return False
    if isinstance(x, list):
        return len(x) == len(y) and all(_same_leaf(u, v) for u, v in zip(x, y))
    if isinstance(x, dict):
        return x.keys() == y.keys() and all(_same_leaf(x[k], y[k]) for k in x)
    if isinstance(x, float):
        return struct.pack("<d", x) == struct.pack("<d", y) or (math.isnan(x) and math.isnan(y))
    return x == y


def compare(path_a, path_b, attrs: bool = True, counts: dict | None = None, notes: list | None = None) -> list[str]:
    """Differences between two HDF5 files, as readable lines (empty if they agree).

    ``counts``, if given, receives the number of datasets and attributes compared. ``notes``, if given,
    receives the differences that change no value, instead of the returned list: an attribute of
    :data:`DESCRIBING` in one file only, a JSON entry ending in :data:`DESCRIBING_SUFFIX` that differs.
    """
    out: list[str] = []
    described = out if notes is None else notes
    counts = {} if counts is None else counts
    counts.update(datasets=0, attributes=0)
    with h5py.File(path_a, "r") as fa, h5py.File(path_b, "r") as fb:
        names_a, names_b = [], []
        fa.visit(names_a.append)
        fb.visit(names_b.append)
        for name in sorted(set(names_a) ^ set(names_b)):
            out.append(f"{name}: only in {path_a if name in names_a else path_b}")
        for name in [""] + sorted(set(names_a) & set(names_b)):
            oa, ob = (fa[name], fb[name]) if name else (fa, fb)
            if isinstance(oa, h5py.Dataset) != isinstance(ob, h5py.Dataset):
                out.append(f"{name}: a dataset in one file, a group in the other")
                continue
            if isinstance(oa, h5py.Dataset):
                counts["datasets"] += 1
                if oa.shape != ob.shape or oa.dtype != ob.dtype:
                    out.append(f"{name}: shape/dtype {oa.shape} {oa.dtype} != {ob.shape} {ob.dtype}")
                elif not _same_value(oa[()], ob[()]):
                    a, b = np.asarray(oa[()]), np.asarray(ob[()])
                    detail = ""
                    if a.dtype.kind in "fiu" and a.size:
                        ne = ~((a == b) | (np.isnan(a) & np.isnan(b)) if a.dtype.kind == "f" else (a == b))
                        diff = np.flatnonzero(ne.ravel())
                        if diff.size:
                            detail = f" ({diff.size} of {a.size} values differ, first at flat index {diff[0]})"
                    out.append(f"{name}: data differ{detail}")
            if attrs:
                for key in sorted(set(oa.attrs) | set(ob.attrs)):
                    if _volatile(key):
                        continue
                    counts["attributes"] += 1
                    if key not in oa.attrs or key not in ob.attrs:
                        where = f"{name or '/'}@{key}"
                        (described if where in DESCRIBING else out).append(f"{where}: only in one file")
                    elif isinstance(oa.attrs[key], h5py.Reference):
                        # object references point into their own file: compare the paths they name
                        ra, rb = fa[oa.attrs[key]].name, fb[ob.attrs[key]].name
                        if ra != rb:
                            out.append(f"{name or '/'}@{key}: references {ra} != {rb}")
                    elif key in ORDERLESS and _same_items(oa.attrs[key], ob.attrs[key]):
                        continue
                    elif not _same_value(oa.attrs[key], ob.attrs[key]):
                        keys = _json_differences(oa.attrs[key], ob.attrs[key])
                        if keys is not None:  # a JSON text (the parameters): the entries that differ
                            for k, line in keys:
                                words = key == "derived_json" and k.endswith(DESCRIBING_SUFFIX)
                                to = described if words else out
                                to.append(f"{name or '/'}@{key}: {line}")
                        else:
                            out.append(f"{name or '/'}@{key}: {oa.attrs[key]!r} != {ob.attrs[key]!r}")
    return out


def add_arguments(ap):
    """The arguments of the command (also ``selfas-graph compare``)."""
    ap.add_argument("a")
    ap.add_argument("b")
    ap.add_argument("--ignore-attrs", action="store_true", help="compare datasets only")


def run(args) -> int:
    """Compare ``args.a`` with ``args.b``, print the differences and the verdict; 1 if they differ."""
    counts: dict = {}
    notes: list = []
    diffs = compare(args.a, args.b, attrs=not args.ignore_attrs, counts=counts, notes=notes)
    for line in diffs:
        print(line)
    print(
        f"{args.a} and {args.b}: {counts['datasets']} datasets and {counts['attributes']} attributes compared, "
        + ("the same, bit for bit" if not diffs else f"{len(diffs)} difference{'' if len(diffs) == 1 else 's'}")
        + (f" (descriptions only, not counted: {', '.join(described(notes))})" if notes else "")
    )
    return 1 if diffs else 0


def described(notes) -> list:
    """The attributes (and JSON entries) that :func:`compare`'s ``notes`` name, each once."""
    names = []
    for line in notes:
        parts = line.split(": ", 2)  # ATTRIBUTE: only in one file, or ATTRIBUTE: KEY: A != B
        names.append(parts[0] if len(parts) < 3 else f"{parts[0]} ({parts[1]})")
    return list(dict.fromkeys(names))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_arguments(ap)
    return run(ap.parse_args(argv))


if __name__ == "__main__":
    sys.exit(main())
