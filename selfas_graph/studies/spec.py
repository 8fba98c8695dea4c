"""The studies file: which ensembles the results page is made from, and the claims it tests.

``docs/studies.toml`` names every study (a scenario, its overrides, seeds, end time and the times
to summarise) and every claim (a measure of a study at a time, the null model it is set against and
the direction the paper's claim predicts). ``selfas-graph study run NAME`` runs a study's seeds,
``selfas-graph study summarise NAME`` writes its small summary from the run files, and
``selfas-graph study page`` writes the tables of docs/results.md from the summaries
(docs/results.md, the paragraph "How this page is made")::

    [study.fig2]
    title = "Fig. 2, case (i)"
    scenario = "scenarios/fig2.toml"
    overrides = []                 # KEY=VALUE, as --set
    seeds = 8                      # seeds first_seed .. first_seed + seeds - 1
    t_end = 600.0
    every = 10.0                   # summarise every this many t0 from 0 to t_end
    table_times = [300.0, 600.0]   # the times of the tables

    [[claim]]
    id = "filaments"
    ...

A top-level ``trajectories_since = "0.4.0"`` names the first version whose trajectories the code
follows now; the page marks a study still made of runs of an older version. A study may name a later
one of its own (``trajectories_since = "0.4.1"`` in its table), where a change moved only some
scenes' trajectories (the tip-tip tree's defaults move only scenes of
``forces.tip_magnetic.tree_above`` rods or more).
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
from pathlib import Path

from ..provenance import version_key

__all__ = ["Claim", "Study", "StudiesError", "Studies", "Sweep", "later_version", "load_studies"]


def later_version(a, b) -> str:
    """The later of two versions ("" is earlier than any); ValueError for one that cannot be read."""
    if not a or not b:
        return a or b
    ka, kb = version_key(a), version_key(b)
    if ka is None or kb is None:
        raise ValueError(f"a version such as '0.4.0', got {(a if ka is None else b)!r}")
    return a if ka > kb else b


class StudiesError(ValueError):
    """A studies file that cannot be used; the message names the file, the entry and the key."""


@dataclasses.dataclass(frozen=True)
class Study:
    """One ensemble: a scenario with overrides over seeds to an end time, summarised at times."""

    name: str
    title: str
    scenario: str
    overrides: tuple[str, ...]
    seeds: int
    first_seed: int
    t_end: float
    every: float
    table_times: tuple[float, ...]
    section: str = ""
    null_of: str = ""
    doc: str = ""
    sweep: str = ""
    sweep_value: float = math.nan
    #: "ensemble" (run files, per-frame measures) or "percolation" (short-circuit times over rod
    #: counts, runs that stop at the short circuit and write no file: ``selfas-graph bench percolation``)
    kind: str = "ensemble"
    counts: tuple[int, ...] = ()
    fields: str = "on"
    #: the study's own ``trajectories_since`` ("" for none): a later first version than the file's
    #: for its runs (``Studies.since`` takes the later of the two)
    trajectories_since: str = ""

    @property
    def times(self) -> list[float]:
        """0, every, 2 every, ... up to t_end (t_end included)."""
        n = int(math.floor(self.t_end / self.every + 1e-9))
        out = [round(k * self.every, 10) for k in range(n + 1)]
        if out[-1] < self.t_end - 1e-9:
            out.append(self.t_end)
        for t in self.table_times:
            if all(abs(t - u) > 1e-9 for u in out):
                out.append(t)
        return sorted(out)


@dataclasses.dataclass(frozen=True)
class Claim:
    """A claim of the paper tested by one measure of a study at one time, against a null model.

    ``expect`` is the direction the claim predicts against the null ("greater" or "less");
    ``null`` names the null model's study (the same measure at the same time), or "" for a claim
    without one yet, whose verdict then says so.
    """

    id: str
    claim: str
    paper: str
    study: str
    measure: str
    time: float
    null: str = ""
    null_measure: str = ""
    expect: str = "greater"
    also: tuple[str, ...] = ()
    #: (t1, t2): test each seed's mean of the measure over the summarised times in [t1, t2] instead of
    #: its value at ``time`` (for a measure that flickers, e.g. rods in filaments as the gap opens and closes)
    window: tuple[float, ...] = ()
    #: the seed counts (study, null model) of each reading of the verdict before this one, in order (a
    #: count read twice is there twice): the k-th reading is tested at a lower level
    #: (docs/model.md "Measures of the paper's claims", its Verdicts)
    looks: tuple[tuple[int, int], ...] = ()


@dataclasses.dataclass(frozen=True)
class Sweep:
    """Studies that differ in one physical parameter: those whose ``sweep`` names this, and the
    paper-scene study ``base`` at ``base_value``, compared at ``time``."""

    name: str
    title: str
    parameter: str
    base: str
    base_value: float
    time: float


@dataclasses.dataclass(frozen=True)
class Studies:
    path: Path
    studies: dict
    claims: tuple
    sweeps: dict = dataclasses.field(default_factory=dict)
    #: the first version whose trajectories the code follows now (the top-level key
    #: ``trajectories_since``): the page marks a study made of runs of an older version ("" marks none)
    trajectories_since: str = ""

    def sweep_points(self, name) -> list:
        """(value, study name) of a sweep, the base included, in order of the value."""
        sw = self.sweeps[name]
        pts = [(sw.base_value, sw.base)] + [(s.sweep_value, s.name) for s in self.studies.values() if s.sweep == name]
        return sorted(pts)

    def compared_times(self, name) -> list[float]:
        """The times at which other entries set a study against ``name``: the table times of the
        studies whose ``null_of`` names it (null models and convergence settings), the time of each
        sweep it is the base or a point of, and the times of the claims on it."""
        times = {t for s in self.studies.values() if s.null_of == name for t in s.table_times}
        member = self.studies[name].sweep if name in self.studies else ""
        times |= {sw.time for sw in self.sweeps.values() if sw.base == name or sw.name == member}
        times |= {c.time for c in self.claims if c.study == name or c.null == name}
        return sorted(times)

    def since(self, name) -> str:
        """The first version whose runs study ``name`` takes: the later of its own ``trajectories_since``
        and the file's."""
        s = self.studies.get(name)
        return later_version(s.trajectories_since if s is not None else "", self.trajectories_since)

    def study(self, name) -> Study:
        if name not in self.studies:
            raise StudiesError(f"{self.path}: no study named {name!r}; the studies are {', '.join(self.studies)}")
        return self.studies[name]


_STUDY_KEYS = {
    "title": str,
    "scenario": str,
    "overrides": list,
    "seeds": int,
    "first_seed": int,
    "t_end": (int, float),
    "every": (int, float),
    "table_times": list,
    "trajectories_since": str,
    "section": str,
    "null_of": str,
    "doc": str,
    "sweep": str,
    "sweep_value": (int, float),
    "kind": str,
    "counts": list,
    "fields": str,
}
_SWEEP_KEYS = {"title": str, "parameter": str, "base": str, "base_value": (int, float), "time": (int, float)}
_CLAIM_KEYS = {
    "id": str,
    "claim": str,
    "paper": str,
    "study": str,
    "measure": str,
    "time": (int, float),
    "null": str,
    "null_measure": str,
    "expect": str,
    "also": list,
    "window": list,
    "looks": list,
}


def _check(where, table, keys, required):
    for k, v in table.items():
        if k not in keys:
            raise StudiesError(f"{where}: unknown key {k!r}; valid keys: {', '.join(keys)}")
        if not isinstance(v, keys[k]) or isinstance(v, bool):
            raise StudiesError(f"{where}.{k}: {v!r} is not of the right type")
    for k in required:
        if k not in table:
            raise StudiesError(f"{where}: missing key {k!r}")


def _numbers(where, key, values, kind=float):
    """The list ``values`` of table key ``key`` as a tuple of ``kind`` (StudiesError naming the key when an
    entry is not a number: a bare ValueError left ``study`` with a traceback)."""
    if any(isinstance(x, bool) or not isinstance(x, (int, float)) for x in values):
        raise StudiesError(f"{where}.{key}: a list of numbers, got {values!r}")
    if kind is int and any(x != int(x) for x in values):
        raise StudiesError(f"{where}.{key}: a list of whole numbers, got {values!r}")
    return tuple(kind(x) for x in values)


def _check_measures(where, claim):
    """A claim's ``measure``, ``null_measure`` and ``also`` name measures a study's summary has (a
    misspelled one gave a row of "n/a" and no verdict, without a word)."""
    from .summary import STUDY_MEASURES

    known = {m.name for m in STUDY_MEASURES}
    for key in ("measure", "null_measure", "also"):
        names = claim.get(key) or []
        for name in [names] if isinstance(names, str) else names:
            if name not in known:
                raise StudiesError(f"{where}.{key}: no measure named {name!r}; valid: {', '.join(sorted(known))}")


def _read_toml(path):
    """The tables of a studies file (StudiesError naming the file when it cannot be read or parsed)."""
    try:
        raw = tomllib.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise StudiesError(f"{path}: cannot read the studies file ({exc.strerror or exc})") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise StudiesError(f"{path}: not a valid TOML file ({exc})") from None
    extra = set(raw) - {"study", "claim", "sweep", "trajectories_since"}
    if extra:
        raise StudiesError(
            f"{path}: unknown key(s) {sorted(extra)}; valid: trajectories_since, [study.NAME], [sweep.NAME], [[claim]]"
        )
    return raw


def _study(where, name, t, since) -> Study:
    """One ``[study.NAME]`` table, checked on its own (its links to other entries: :func:`_check_links`)."""
    if not isinstance(t, dict):
        raise StudiesError(f"{where}: must be a table")
    _check(where, t, _STUDY_KEYS, ("scenario", "seeds", "t_end"))
    t_end = float(t["t_end"])
    every = float(t.get("every", t_end / 4))
    if not (0 < t_end < math.inf and 0 < every < math.inf and t["seeds"] >= 1 and t.get("first_seed", 1) >= 0):
        raise StudiesError(f"{where}: t_end and every must be finite and positive, seeds >= 1, first_seed >= 0")
    if not all(isinstance(o, str) for o in t.get("overrides", [])):
        raise StudiesError(f"{where}.overrides: a list of strings KEY=VALUE, got {t['overrides']!r}")
    table_times = _numbers(where, "table_times", t.get("table_times", [t_end]))
    own = t.get("trajectories_since", "")
    if own and (version_key(own) is None or (since and version_key(own) < version_key(since))):
        raise StudiesError(
            f'{where}.trajectories_since: a version such as "0.4.1", not earlier than the file\'s '
            f"trajectories_since ({since or 'none'}), got {own!r}"
        )
    if any(not 0 <= x <= t_end for x in table_times):
        raise StudiesError(f"{where}.table_times: every time must lie in [0, t_end = {t_end:g}]")
    st = Study(
        name=name,
        title=t.get("title", name),
        scenario=t["scenario"],
        overrides=tuple(str(o) for o in t.get("overrides", [])),
        seeds=int(t["seeds"]),
        first_seed=int(t.get("first_seed", 1)),
        t_end=t_end,
        every=every,
        table_times=table_times,
        section=t.get("section", ""),
        null_of=t.get("null_of", ""),
        doc=t.get("doc", ""),
        sweep=t.get("sweep", ""),
        sweep_value=float(t.get("sweep_value", math.nan)),
        kind=t.get("kind", "ensemble"),
        counts=_numbers(where, "counts", t.get("counts", []), int),
        fields=t.get("fields", "on"),
        trajectories_since=own,
    )
    if st.kind not in ("ensemble", "percolation"):
        raise StudiesError(f"{where}.kind: 'ensemble' or 'percolation', got {st.kind!r}")
    if st.kind == "percolation" and (not st.counts or min(st.counts) < 1 or st.fields not in ("on", "off")):
        raise StudiesError(f"{where}: a percolation study needs counts (rods, >= 1) and fields 'on' or 'off'")
    return st


def _sweep(where, name, t, studies) -> Sweep:
    """One ``[sweep.NAME]`` table, whose base must name a study."""
    if not isinstance(t, dict):
        raise StudiesError(f"{where}: must be a table")
    _check(where, t, _SWEEP_KEYS, tuple(_SWEEP_KEYS))
    if t["base"] not in studies:
        raise StudiesError(f"{where}.base: no study named {t['base']!r}")
    return Sweep(name, t["title"], t["parameter"], t["base"], float(t["base_value"]), float(t["time"]))


def _check_links(path, studies, sweeps):
    """Each study's ``null_of`` and ``sweep`` name an entry of the file; a sweep's study has its value."""
    for st in studies.values():
        if st.null_of and st.null_of not in studies:
            raise StudiesError(f"{path}: study.{st.name}.null_of: no study named {st.null_of!r}")
        if st.sweep and st.sweep not in sweeps:
            raise StudiesError(f"{path}: study.{st.name}.sweep: no sweep named {st.sweep!r}")
        if st.sweep and not math.isfinite(st.sweep_value):
            raise StudiesError(f"{path}: study.{st.name}: a study of a sweep needs its sweep_value")
        if math.isfinite(st.sweep_value) and not st.sweep:
            raise StudiesError(f"{path}: study.{st.name}.sweep_value: given without the sweep it is a point of")
    for sw in sweeps.values():
        if studies[sw.base].sweep == sw.name:
            raise StudiesError(
                f"{path}: sweep.{sw.name}.base: {sw.base} is the sweep's base at base_value; it names the sweep "
                "itself too (sweep, sweep_value): give it once"
            )
        points = [sw.base, *(s.name for s in studies.values() if s.sweep == sw.name)]
        off = [st for st in points if not _summarised_at(studies[st], sw.time)]
        if off:
            raise StudiesError(
                f"{path}: sweep.{sw.name}.time {sw.time:g} is no summarised time of study {off[0]} (its times: "
                f"every {studies[off[0]].every:g} to t_end and table_times)"
            )


def _summarised_at(study, t) -> bool:
    """Whether ``t`` is one of ``study``'s summarised times (:attr:`Study.times`)."""
    return any(abs(t - x) <= 1e-9 * max(1.0, abs(t)) for x in study.times)


def _claim(where, c, studies) -> Claim:
    """One ``[[claim]]``: its studies exist, its measures are summarised, its time and window lie
    within both studies' runs."""
    if not isinstance(c, dict):
        raise StudiesError(f"{where}: must be a table")
    _check(where, c, _CLAIM_KEYS, ("id", "claim", "paper", "study", "measure", "time"))
    for key in ("study", "null"):
        if c.get(key) and c[key] not in studies:
            raise StudiesError(f"{where}.{key}: no study named {c[key]!r}")
    _check_measures(where, c)
    w = _numbers(where, "window", c.get("window", []))
    if w and (len(w) != 2 or not w[0] < w[1]):
        raise StudiesError(f"{where}.window: [t1, t2] with t1 < t2, got {list(w)!r}")
    for key in ("study", "null"):
        st = studies.get(c.get(key, ""))
        if st is not None and any(not 0 <= x <= st.t_end for x in (c["time"], *w)):
            raise StudiesError(
                f"{where}: time {c['time']:g} and window {list(w)} must lie in [0, t_end = {st.t_end:g}] of "
                f"study {st.name!r} ({key})"
            )
    if c.get("expect", "greater") not in ("greater", "less"):
        raise StudiesError(f"{where}.expect: 'greater' or 'less', got {c['expect']!r}")
    if c.get("null") and c["null"] == c["study"]:
        raise StudiesError(f"{where}.null: {c['null']!r} is the claim's own study; name its null model")
    for key in ("study", "null"):
        st = studies.get(c.get(key, ""))
        if st is None:
            continue
        if not _summarised_at(st, c["time"]):
            raise StudiesError(
                f"{where}.time {c['time']:g} is no summarised time of study {st.name!r} ({key}): give one of its "
                "times (every to t_end, and table_times)"
            )
        if w and not any(w[0] - 1e-9 <= x <= w[1] + 1e-9 for x in st.times):
            raise StudiesError(f"{where}.window {list(w)} holds no summarised time of study {st.name!r} ({key})")
    looks = c.get("looks", [])
    counts = [n for x in looks if isinstance(x, list) and len(x) == 2 for n in x]
    if len(counts) != 2 * len(looks) or any(type(n) is not int or n < 1 for n in counts):
        raise StudiesError(f"{where}.looks: a list of [seeds of the study, seeds of the null model], got {looks!r}")
    return Claim(
        **{k: v for k, v in c.items() if k not in ("time", "also", "window", "looks")},
        time=float(c["time"]),
        also=tuple(c.get("also", [])),
        window=w,
        looks=tuple(tuple(int(n) for n in x) for x in looks),
    )


def load_studies(path) -> Studies:
    """Read and check a studies file (StudiesError naming the file and key when it is wrong)."""
    path = Path(path)
    raw = _read_toml(path)
    since = raw.get("trajectories_since", "")
    if not isinstance(since, str) or (since and version_key(since) is None):
        raise StudiesError(f'{path}: trajectories_since: a version such as "0.4.0", got {since!r}')
    for key, kind in (("study", dict), ("sweep", dict), ("claim", list)):
        if not isinstance(raw.get(key, kind()), kind):
            what = (
                "tables [study.NAME]"
                if key == "study"
                else "tables [sweep.NAME]"
                if key == "sweep"
                else "[[claim]] tables"
            )
            raise StudiesError(f"{path}: {key}: {what}, got {raw[key]!r}")
    studies = {name: _study(f"{path}: study.{name}", name, t, since) for name, t in (raw.get("study") or {}).items()}
    sweeps = {name: _sweep(f"{path}: sweep.{name}", name, t, studies) for name, t in (raw.get("sweep") or {}).items()}
    _check_links(path, studies, sweeps)
    claims = tuple(_claim(f"{path}: claim[{k}]", c, studies) for k, c in enumerate(raw.get("claim") or []))
    ids = [c.id for c in claims]
    twice = sorted({i for i in ids if ids.count(i) > 1})
    if twice:
        raise StudiesError(f"{path}: claim id {twice[0]!r} is given to more than one claim; each claim needs its own")
    return Studies(path=path, studies=studies, claims=claims, sweeps=sweeps, trajectories_since=since)
