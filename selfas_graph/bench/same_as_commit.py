"""Check that the working tree writes the run files a git commit writes, bit for bit.

Usage::

    selfas-graph bench same_as_commit [--commit REV] [--keep DIR] SCENARIO [SCENARIO ...]
        [--set KEY=VALUE ...]

For each scenario, exports ``REV`` (default ``HEAD``) with ``git archive`` into a temporary
folder, runs ``selfas-graph simulate`` once with that code and once with the working tree
(same Python, run from a temporary folder, each checked to import the code meant; same thread count: ``NUMBA_NUM_THREADS`` and ``OMP_NUM_THREADS`` are set to
``--threads``, default 1), and compares the two run files with ``selfas_graph/bench/same_run.py``. The
``--set`` overrides apply to every scenario. A scenario may carry its own overrides after a
``+``: ``scenarios/fig8_quick.toml+run.t_end=6+forces.external_filament.diameter=0.6``.
Exits 1 if any pair differs. Attributes that only describe (``same_run.DESCRIBING``, the words of
``derived_json``'s ``*_sum`` entries) are named but not counted. Parameters added since ``REV`` that the working tree's file stores at their
defaults are not a difference (as for an ensemble's seed files, ``model/parameter_match.py``): the verdict
names them.

Use it before committing a change that should keep a run's results: e.g. ::

    selfas-graph bench same_as_commit scenarios/quick.toml \\
        scenarios/fig8_quick.toml+run.t_end=6+forces.external_filament.diameter=0.6

(the second scene is case (ii) with currents flowing from t = 3.5 on).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
from pathlib import Path

from ..io.layout import PROVENANCE
from .same_run import compare, described

#: the folder that holds the working tree's package (and its git checkout)
ROOT = Path(__file__).resolve().parents[2]

#: run in the code folder given by PYTHONPATH, and check that it is that code which runs (the
#: working tree's editable install, or a current folder holding selfas_graph, would win otherwise)
RUNNER = """import sys
from pathlib import Path
import selfas_graph
assert Path(selfas_graph.__file__).resolve().parent.parent == Path(sys.argv.pop(1)).resolve(), selfas_graph.__file__
from selfas_graph.cli.main import main
sys.exit(main())
"""


def export(commit: str, into: Path, paths: list[str]) -> None:
    """``git archive COMMIT PATHS`` unpacked into ``into`` (SystemExit naming the commit and paths
    when git refuses, e.g. an unknown commit or a path the commit lacks)."""
    got = subprocess.run(["git", "archive", commit, *paths], cwd=ROOT, capture_output=True)
    if got.returncode != 0:
        raise SystemExit(f"git archive {commit} {' '.join(paths)}: {got.stderr.decode(errors='replace').strip()}")
    subprocess.run(["tar", "-x", "-C", str(into)], input=got.stdout, check=True)


def _simulate(code: Path, scenario: str, sets: list[str], out: Path, threads: int, cwd: Path) -> None:
    env = dict(os.environ, PYTHONPATH=str(code), NUMBA_NUM_THREADS=str(threads), OMP_NUM_THREADS=str(threads))
    cmd = [
        sys.executable,
        "-c",
        RUNNER,
        str(code),
        "simulate",
        str(Path(scenario).resolve()),
        "-o",
        str(out),
        "--progress",
        "none",
        "--force",
    ]
    for s in sets:
        cmd += ["--set", s]
    r = subprocess.run(cmd, env=env, cwd=cwd, capture_output=True, text=True)
    if r.returncode != 0:
        raise SystemExit(f"{code}: simulate {scenario} failed (exit {r.returncode}):\n{r.stdout}{r.stderr}")


#: the attribute that holds a run's parameters (``io/layout.py::PROVENANCE``), as ``same_run.compare`` names it
PARAMETERS = f"{PROVENANCE}@parameters_json"


def _parameters_added_at_default(before: Path, after: Path) -> list[str]:
    """The parameter keys the working tree's run file stores and the commit's lacks, when those are all
    that differ and each is at its default (a parameter added since the commit that leaves a run as it
    was, as ``model/parameter_match.py`` counts it); otherwise []. Every key of the commit's file must be in
    the working tree's with the same value (no key is exempt, unlike an ensemble's ``run.t_end``)."""
    import json

    import h5py

    from ..model.parameter_match import _flat, _newer_key_at_default

    with h5py.File(before, "r") as a, h5py.File(after, "r") as b:
        old, new = (_flat(json.loads(f[PROVENANCE].attrs["parameters_json"])) for f in (a, b))
    added = sorted(set(new) - set(old))
    if not added or any(k not in new or new[k] != v for k, v in old.items()):
        return []
    return added if all(_newer_key_at_default(k, old, new) for k in added) else []


def scenario_specs(words) -> list:
    """The command line's scenario words as one ``FILE+KEY=VALUE...`` spec per scenario: an override given as
    a word of its own (``+KEY=VALUE``) joins the scenario before it."""
    specs = []
    for word in words:
        if word.startswith("+"):
            if not specs:
                raise ValueError(f"the override {word} comes before any scenario file; put it after its scenario")
            specs[-1] += word
        else:
            specs.append(word)
    return specs


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "scenarios",
        nargs="+",
        help="scenario files, each optionally followed by +KEY=VALUE overrides of its own (joined to its name or "
        "as the next arguments: fig2.toml+run.t_end=5 or fig2.toml +run.t_end=5)",
    )
    ap.add_argument("--commit", default="HEAD", help="the reference commit (default HEAD)")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override for every scenario")
    ap.add_argument("--threads", type=int, default=1, help="numba threads of both runs (default 1)")
    ap.add_argument("--keep", type=Path, help="keep the run files in this folder")
    args = ap.parse_args(argv)
    try:
        specs = scenario_specs(args.scenarios)
    except ValueError as exc:
        ap.error(str(exc))
    with tempfile.TemporaryDirectory(prefix="same_as_commit_") as tmp:
        tmp = Path(tmp)
        base = tmp / "code"
        base.mkdir()
        export(args.commit, base, ["selfas_graph"])
        out_dir = (args.keep or tmp).resolve()
        out_dir.mkdir(parents=True, exist_ok=True)
        failed = 0
        for i, spec in enumerate(specs):
            scenario, *own = spec.split("+")
            sets = args.set + own
            name = f"{i}_{Path(scenario).stem}"
            before, after = out_dir / f"{name}_commit.h5", out_dir / f"{name}_tree.h5"
            _simulate(base, scenario, sets, before, args.threads, tmp)
            _simulate(ROOT, scenario, sets, after, args.threads, tmp)
            counts: dict = {}
            notes: list = []
            diffs = compare(before, after, counts=counts, notes=notes)
            added = _parameters_added_at_default(before, after)
            if added:
                diffs = [line for line in diffs if not line.startswith(PARAMETERS)]
            for line in diffs:
                print(f"  {line}")
            print(
                f"{spec}: {args.commit} and the working tree: {counts['datasets']} datasets and "
                f"{counts['attributes']} attributes compared, "
                + ("the same, bit for bit" if not diffs else f"{len(diffs)} differences")
                + (
                    f" (the working tree's stored parameters add {', '.join(added)}, each at its default)"
                    if added
                    else ""
                )
                + (f" (descriptions only: {', '.join(described(notes))})" if notes else "")
            )
            failed += bool(diffs)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
