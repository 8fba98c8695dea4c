"""Write the scenario reference ``docs/scenarios.md`` from the schema in ``selfas_graph.model.params``.

The parameter dataclasses hold every key's default, admissible range and doc
string in their field metadata (``params.spec``); this script walks them from
:class:`~selfas_graph.model.params.Parameters` down and renders one table per
section, so the reference cannot drift from what the loader accepts.

Usage::

    selfas-graph bench scenario_docs           # write docs/scenarios.md
    selfas-graph bench scenario_docs --check   # exit 1 if docs/scenarios.md is not up to date

``render()`` returns the text; ``tests/unit/test_docs.py`` compares it with the file.
"""

from __future__ import annotations

import argparse
import dataclasses
import re
import sys
import typing
from pathlib import Path

from selfas_graph.io.scenario import unwrap_optional
from selfas_graph.model import params as P

#: the checkout whose docs/scenarios.md is written
ROOT = Path(__file__).resolve().parents[2]
OUTPUT = ROOT / "docs" / "scenarios.md"
REGENERATE = "selfas-graph bench scenario_docs"


# ----------------------------------------------------------------------------- schema walk


@dataclasses.dataclass
class Key:
    """One scalar or array value of a scenario (a leaf of the schema)."""

    path: str
    type: str
    default: str
    valid: str
    doc: str


@dataclasses.dataclass
class Section:
    """One TOML table: its keys and its sub-tables."""

    path: str
    intro: str
    optional: bool
    keys: list = dataclasses.field(default_factory=list)
    tables: list = dataclasses.field(default_factory=list)


def _class_doc(cls) -> str:
    """First paragraph of a dataclass's own docstring ('' for the generated signature docstring)."""
    doc = cls.__doc__ or ""
    if not doc or doc.startswith(cls.__name__ + "("):
        return ""
    return " ".join(doc.strip().split("\n\n")[0].split())


def _sentence(text: str) -> str:
    text = " ".join(text.split())
    if not text:
        return text
    text = text[0].upper() + text[1:]
    return text if text.endswith(".") else text + "."


def _shape(value):
    if isinstance(value, (list, tuple)):
        return (len(value),) + (_shape(value[0]) if value else ())
    return ()


def _number(value) -> str:
    """A number as it would be written in TOML (exact: repr for floats)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value)
    return str(value)


def _toml(value) -> str:
    if isinstance(value, str):
        return f'"{value}"'
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml(v) for v in value) + "]"
    return _number(value)


#: a leading "term 6:" or "Term 11, case (ii):"
_TERM = re.compile(r"^\s*term \d+(, case \(\w+\))?:\s*", re.IGNORECASE)
_DERIVED = re.compile(r"\(default:?\s*([^()]*(?:\([^()]*\)[^()]*)*)\)")


def _derived_rule(path: str, doc: str) -> str:
    """The '(default ...)' rule that a doc string gives for a value that defaults to None."""
    m = _DERIVED.search(doc)
    if not m:
        raise ValueError(
            f"{path} defaults to None but its doc string gives no '(default: ...)' rule; "
            "say in selfas_graph/model/params.py what the value is when the key is absent"
        )
    return m.group(1).strip()


def _type_and_valid(tp, meta, default):
    """(type, valid values) of a leaf, from its annotation, metadata and default."""
    if tp is tuple:
        shape = _shape(default)
        if meta.get("length") and len(shape) == 1:
            shape = (meta["length"],)
        if len(shape) == 1:
            return f"array of {shape[0]} numbers", "finite numbers"
        return "array of " + " x ".join(str(s) for s in shape) + " numbers", "finite numbers"
    if tp is bool:
        return "boolean", "`true`, `false`"
    if tp is str:
        choices = meta.get("choices")
        if choices:
            return "string", "one of " + ", ".join(f'`"{c}"`' for c in choices)
        return "string", "any string"
    name = {int: "integer", float: "number"}.get(tp)
    if name is None:
        raise TypeError(f"no documentation rule for the type {tp!r}")
    bounds = []
    for key, word in (("ge", ">="), ("gt", ">"), ("le", "<="), ("lt", "<")):
        b = meta.get(key)
        if b is not None:
            bounds.append(f"{word} {b:g}")
    if bounds:
        return name, " and ".join(bounds)
    return name, "any finite number" if tp is float else "any integer"


def walk(cls=None, prefix="", instance=None, intro="", optional=False) -> Section:
    """The schema below ``cls`` as a tree of :class:`Section` objects.

    Parameters
    ----------
    cls : dataclass type, default :class:`Parameters`
    prefix : str
        Dotted path of the table ('' for the root).
    instance : cls instance, optional
        Holds the defaults to show (a sub-table's defaults may differ from its
        class defaults, e.g. ``rods.electric_charge``); default ``cls()``.
    """
    cls = P.Parameters if cls is None else cls
    instance = cls() if instance is None else instance
    section = Section(prefix, intro, optional)
    hints = typing.get_type_hints(cls)
    for f in dataclasses.fields(cls):
        path = f"{prefix}.{f.name}" if prefix else f.name
        tp, is_optional = unwrap_optional(hints[f.name])
        meta = f.metadata
        value = getattr(instance, f.name)
        doc = meta.get("doc", "")
        if dataclasses.is_dataclass(tp):
            sub_instance = tp() if value is None else value
            text = _sentence(doc)
            own = _class_doc(tp)
            if _TERM.match(doc):  # "term 6: ..." already numbers the term: drop the class doc's prefix
                own = _TERM.sub("", own)
            if own and own.rstrip(".").lower() != doc.rstrip(".").lower():
                text = f"{text} {_sentence(own)}"
            section.tables.append(walk(tp, path, sub_instance, text, is_optional))
            continue
        type_name, valid = _type_and_valid(tp, meta, value)
        if value is None:
            default = f"(derived) {_derived_rule(path, doc)}"
        else:
            default = f"`{_toml(value)}`"
        section.keys.append(Key(path, type_name, default, valid, doc))
    return section


def key_paths(section: Section | None = None) -> set:
    """Every valid dotted path of the schema: tables and keys (used by tests/unit/test_docs.py)."""
    section = walk() if section is None else section
    out = {k.path for k in section.keys}
    for t in section.tables:
        out.add(t.path)
        out |= key_paths(t)
    return out


# ----------------------------------------------------------------------------- rendering

HEADER = """\
# Scenario reference

<!-- Generated by selfas_graph/bench/scenario_docs.py from selfas_graph/model/params.py. Do not edit by hand:
     change the doc strings there and run `selfas-graph bench scenario_docs`. -->

A scenario is a TOML file that describes one run: the rods, their initial placement, the force
terms that act, the integrator, the circuit and the output. This page lists every key, its type,
its default and its valid values. It is generated from the schema in
`selfas_graph/model/params.py`, the same schema the loader (`selfas_graph/io/scenario.py`) checks
files against, so it cannot list a key the loader does not accept. All values are in the reduced
units of [docs/model.md](model.md) (lengths in rod lengths L, times in t0, fields in B0, ...).

Loading reports every problem at once, each naming its key path and what would be valid: unknown
keys (with a "did you mean"), wrong types, values out of range, and the rules across keys listed
below. The command-line tool exits with code 2 on an invalid scenario and writes nothing.
Every number (each entry of an array too) is 0 or between 1e-30 and 1e+30 in magnitude, beside
its own range below: products of a few such numbers (q^2, B q, 1 / R_D^2, ...) stay finite in
double precision, so no force or energy derived from a valid scenario overflows to inf or NaN.

## Example

A scene of 100 rods between electrodes with the short-range terms, a uniform field and the
circuit (every key not written takes its default):

```toml
[scenario]
name = "example"
seed = 7

[rods]
count = 100
magnetic_charge = { distribution = "uniform", low = 0.6666666666666666, high = 2.0 }
electric_charge = { distribution = "magnetic" }   # Z_i = the rod's magnetic charge

[placement]
box = [[-4.0, 4.0], [-4.0, 4.0], [-2.0, 2.0]]     # both tips of every rod start in here

[forces.tip_magnetic]                             # term 1 has no keys: the table switches it on
[forces.tip_brake]
coefficient = 100.0
[forces.ambient_brake]                            # on, with the default M_br = 1.5
[forces.uniform_field]
B = [0.0, 0.0, 0.5]
[forces.yukawa]
screening_length = 1.0
[forces.electrodes]
gap = 4.0                                         # planes at z = -2 and z = +2

[circuit]
delta_J0 = 2.23

[integrator]
dt = 5e-4

[run]
t_end = 2.0
```

## Changing values on the command line: `--set key=value`

```bash
selfas-graph simulate scenarios/quick.toml --set integrator.dt=2.5e-4 --set run.t_end=1.0
selfas-graph simulate scenarios/quick.toml --set "forces.uniform_field.B=[0, 0, 1.5]"
selfas-graph simulate scenarios/quick.toml --set integrator.bond_force=paper
```

- The key is the dotted path of this page; the value is written as in TOML (`5e-4`, `true`,
  `"paper"`, `[0, 0, 1.5]`). A bare word that is not TOML is taken as a string, so
  `integrator.bond_force=paper` works without quotes. Quote arrays for the shell.
- An override goes through the same checks as the file. `--set` can be repeated.
- `--t-end T` is a shortcut for `--set run.t_end=T`.
- From Python: `selfas_graph.load_scenario(path, overrides=["integrator.dt=5e-4"])`.

## Rods that differ: lengths, resistances, contacts

By default every rod has length 1 and resistance R0 = 1, and contacts are ideal (the paper's
equal rods). Three keys change that ([model.md section 2](model.md#2-rods),
[section 7](model.md#7-circuit)); a scene without them runs exactly as before, at the same cost.

```toml
[rods]
length = { distribution = "uniform", low = 0.5, high = 1.5 }  # units L, the mean length: mean 1
resistance = { value = 1.0, per_length = true }              # R_i = R0 l_i

[contacts]
resistance = 2.0                                             # r per contact, units R0; 0 = ideal
```

- `rods.length` and `rods.resistance` take a number (the same for every rod) or a table with
  `distribution` = `constant`, `uniform` or `two_level`, as the charges do. The length law
  must have mean 1 (L is the mean rod length, and the units are built on it).
- `scenarios/quick_mixed.toml` is the quick scene with these three keys.

## Switching terms on and off

The force terms (the `[forces.*]` tables) and `[circuit]` are optional sections. A term is **on
when its table is present**, even empty (`[forces.tip_magnetic]`), and off when it is absent; a
term that is off is not computed at all.

- `--set forces.yukawa=false` switches a term off (so does `yukawa = false` under `[forces]`).
- `--set forces.yukawa=true` switches it on with its defaults where the scenario has it off; a term
  already on keeps the scenario's values (true is then no change).
- Setting a key of a term that is off, e.g. `--set forces.yukawa.tolerance=1e-6`, switches the
  term on, with the other keys at their defaults.
- `--set circuit=false` removes the circuit; then no current flows, and terms 9 and 10 must be
  off as well (see the rules below).

## Rules across keys

Besides each key's own range, `selfas_graph.io.scenario.check_consistency` requires:

- each range of `placement.box` is `[low, high]` with `low < high` and within +-1e6, and the box's
  diagonal is longer than the longest rod (length 1, or the largest `rods.length` allows);
- the rods fit the box: the exclusion volume `2 count (pi/6) min_tip_distance^3 / box volume`
  is at most 0.3 (beyond that the random placement stalls);
- with `[forces.electrodes]`, the z range of `placement.box` lies between the planes
  `z = -gap/2` and `z = +gap/2`;
- `distribution = "magnetic"` is valid for `rods.electric_charge` only; with
  `distribution = "uniform"`, `low <= high` (charges, lengths and resistances alike);
- `rods.length`, where set, has mean 1 (the unit of length) and its shortest rod is at least
  `rods.diameter`;
- `integrator.current_every` is 0 or a multiple of `integrator.slow_every`;
- `[circuit]` needs a conductor to apply its bias: {conductors}; and `contacts.enabled`;
- `[forces.current_field]` and `[forces.current_lorentz]` need `[circuit]` (rod currents come
  from the circuit solve);
- with `[circuit]`, the resistances of the rods (`rods.resistance`, times the lengths where per unit
  length) and of the contacts (`contacts.resistance`, unless 0) span at most a factor 1e6: beyond
  it the Kirchhoff solve's round-off makes the currents wrong;
- a `two_level` `rods.length` gives exactly `round(high_fraction * count)` rods the high value: the
  mean of that draw is within 1 % of 1;
- `run.t_end` is at most 1e12 steps of `integrator.dt`;
- `output.interval >= integrator.dt`; an interval that is no whole number of steps is rounded to
  the nearest one, and `simulate` prints the interval it uses (a frame is also written at the end).

The placement can still fail at run time (no free spot for a rod in `placement.max_attempts`
draws); the message names the keys to change.
"""


def _cell(text: str) -> str:
    return " ".join(str(text).split()).replace("|", "\\|")


def _render_section(section: Section, depth: int, lines: list) -> None:
    hashes = "#" * min(depth, 6)
    lines.append(f"{hashes} `[{section.path}]`")
    lines.append("")
    intro = section.intro
    if section.optional:
        intro += (
            f" Optional: on when the table `[{section.path}]` is present, off when it is absent"
            f" (`--set {section.path}=false`)."
        )
    if intro:
        lines.append(intro.strip())
        lines.append("")
    if section.keys:
        lines.append("| key | type | default | valid | description |")
        lines.append("|---|---|---|---|---|")
        for k in section.keys:
            lines.append(f"| `{k.path}` | {_cell(k.type)} | {_cell(k.default)} | {_cell(k.valid)} | {_cell(k.doc)} |")
        lines.append("")
    elif not section.tables:
        lines.append("No keys: the table alone switches this on.")
        lines.append("")
    for t in section.tables:
        _render_section(t, depth + 1, lines)


def render() -> str:
    """The text of docs/scenarios.md for the schema as it is now."""
    root = walk()
    force_tables = {sub.path for t in root.tables if t.path == "forces" for sub in t.tables}
    conductors = ["`[forces.electrodes]` (case (i))"]
    if "forces.external_filament" in force_tables:
        conductors.append("`[forces.external_filament]` (case (ii))")
    lines = [HEADER.replace("{conductors}", " or ".join(conductors))]
    lines.append("## Sections")
    lines.append("")
    for t in root.tables:
        lines.append(f"- [`[{t.path}]`](#{t.path}): {t.intro}")
    lines.append("")
    for t in root.tables:
        lines.append(f'<a id="{t.path}"></a>')
        lines.append("")
        _render_section(t, 2, lines)
    return "\n".join(lines).rstrip("\n") + "\n"


# ----------------------------------------------------------------------------- command line


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(
        description=f"Write docs/scenarios.md of the source checkout the package runs from ({OUTPUT}) from "
        "selfas_graph.model.params."
    )
    parser.add_argument(
        "--check",
        action="store_true",
        help="do not write; exit 1 if docs/scenarios.md differs from what would be written",
    )
    args = parser.parse_args(argv)
    if not (ROOT / "pyproject.toml").exists():  # an installed package: its folder is no checkout
        where = ROOT / "selfas_graph"
        print(
            f"selfas_graph runs from {where}, not from a source checkout: no docs/scenarios.md to write",
            file=sys.stderr,
        )
        return 2
    text = render()
    rel = OUTPUT.relative_to(ROOT)
    if args.check:
        current = OUTPUT.read_text(encoding="utf-8") if OUTPUT.exists() else None
        if current != text:
            what = "is missing" if current is None else "is out of date with selfas_graph/model/params.py"
            print(f"{rel} {what}; regenerate it with: {REGENERATE}", file=sys.stderr)
            return 1
        print(f"{rel} is up to date")
        return 0
    OUTPUT.parent.mkdir(parents=True, exist_ok=True)
    OUTPUT.write_text(text, encoding="utf-8")
    print(f"wrote {rel}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
