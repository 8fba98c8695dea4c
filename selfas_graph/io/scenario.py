"""Scenario files: TOML -> schema check -> defaults -> frozen :class:`Parameters`.

Loading goes raw dict -> overrides (``--set key=value``) -> schema check against
the dataclasses of :mod:`selfas_graph.model.params` (unknown keys with a "did
you mean", wrong types and out-of-range values, each naming its key path) ->
cross-field consistency checks -> frozen parameters. All problems found are
reported together in one :class:`ScenarioError`; nothing is written before
loading succeeds.
"""

from __future__ import annotations

import dataclasses
import difflib
import math
import numbers
import os
import tomllib
import typing
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..model import params as P
from ..model.placement import high_count
from ..model.validate import MAX_RESISTANCE_SPREAD, as_decimal

#: every float of a scenario is 0 or within these magnitudes: products of up to ten of them (q^2 B / r*^3 ...)
#: stay finite in double precision (1e30^10 = 1e300), and reciprocals of tiny ones (1 / R_D^2 ...) too
MIN_MAGNITUDE = 1e-30
MAX_MAGNITUDE = 1e30


class ScenarioError(ValueError):
    """Invalid scenario or override. ``problems`` lists one message per problem."""

    def __init__(self, problems, source=None):
        self.problems = list(problems)
        self.source = source
        head = f"invalid scenario {source}" if source else "invalid scenario"
        super().__init__(head + ":\n" + "\n".join("  - " + p for p in self.problems))


@dataclass(frozen=True)
class Scenario:
    """A loaded scenario: the resolved parameters and where they came from."""

    params: P.Parameters
    text: str
    path: Path | None
    overrides: tuple = ()

    @property
    def output_path(self) -> Path:
        if self.params.output.file:
            return Path(self.params.output.file)
        stem = self.path.stem if self.path is not None else self.params.scenario.name
        return Path(stem + ".h5")


def load_scenario(source, overrides=(), t_end=None) -> Scenario:
    """Load and validate a scenario.

    Parameters
    ----------
    source : str or Path
        A ``.toml`` file.
    overrides : iterable of str
        ``"section.key=value"`` strings; values are TOML (``1e-3``, ``[0, 0, 1]``,
        ``"paper"``); a bare word is taken as a string.
    t_end : float, optional
        Shortcut for ``run.t_end``.

    Raises
    ------
    ScenarioError
        Naming every invalid key and what would be valid.
    """
    if not isinstance(source, (str, os.PathLike)):
        raise TypeError(f"load_scenario(source): the path of a scenario file (TOML), got {source!r}")
    path = Path(source)
    try:
        raw_bytes = path.read_bytes()
    except FileNotFoundError:
        where = "" if path.is_absolute() else f" (a relative path, read from the working directory {Path.cwd()})"
        raise ScenarioError([f"file not found: {path}{where}"], source=path) from None
    except IsADirectoryError:
        raise ScenarioError([f"{path} is a directory, not a scenario file"], source=path) from None
    except OSError as exc:
        raise ScenarioError([f"cannot read {path}: {exc.strerror}"], source=path) from None
    try:
        text = raw_bytes.decode("utf-8")
    except UnicodeDecodeError:
        raise ScenarioError([f"{path} is not a UTF-8 text file (is it a TOML scenario?)"], source=path) from None
    return scenario_from_text(text, path=path, overrides=overrides, t_end=t_end)


def scenario_from_text(text, path=None, overrides=(), t_end=None) -> Scenario:
    """As :func:`load_scenario`, from TOML text."""
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError([f"not valid TOML: {exc}"], source=path) from None
    except ValueError as exc:  # e.g. an integer of more digits than Python converts
        raise ScenarioError([f"not a usable scenario: {exc}"], source=path) from None
    except RecursionError:
        raise ScenarioError(["not valid TOML: arrays or tables nested too deeply"], source=path) from None
    if isinstance(overrides, (str, bytes, dict)) or overrides is None:
        raise ScenarioError(
            [f"overrides: give a list of 'key=value' strings, e.g. ['integrator.dt=5e-4'], got {overrides!r}"],
            source=path,
        )
    overrides = tuple(overrides)
    problems = []
    for item in overrides:
        problems += _apply_override(raw, item)
    if t_end is not None:
        raw.setdefault("run", {})
        if isinstance(raw["run"], dict):
            raw["run"]["t_end"] = t_end
    if problems:
        raise ScenarioError(problems, source=path)
    params = _build(P.Parameters, raw, "", problems)
    if not problems:
        problems += check_consistency(params)
    if problems:
        raise ScenarioError(problems, source=path)
    return Scenario(params=params, text=text, path=path, overrides=overrides)


def check_parameters(params: P.Parameters) -> None:
    """Validate parameters made in Python (``Parameters(...)``, ``dataclasses.replace``) as a
    scenario file is validated; raises :class:`ScenarioError` with the same messages. A section
    given as a dict (``Parameters(rods={"count": 5})``) is named: it must be the section's own
    parameters, as :meth:`~selfas_graph.Parameters.replace` makes them from a dict."""
    built = parameters_from_dict(params.to_raw())
    wrong = [
        f"{f.name}: a {type(getattr(params, f.name)).__name__} where the section's parameters "
        f"({type(getattr(built, f.name)).__name__}) belong; give the changes to Parameters().replace("
        f"{f.name}={{...}}) or Parameters.from_dict({{'{f.name}': {{...}}}})"
        for f in dataclasses.fields(params)
        if getattr(built, f.name) is not None and not isinstance(getattr(params, f.name), type(getattr(built, f.name)))
    ]
    if wrong:
        raise ScenarioError(wrong)


def parameters_from_dict(raw: dict, source=None) -> P.Parameters:
    """Validate a nested dict (as from TOML) into :class:`Parameters`; raises :class:`ScenarioError`."""
    if not isinstance(raw, dict):
        raise ScenarioError([f"parameters: expected a table (a dict of sections), got {type(raw).__name__}"], source)
    problems = []
    params = _build(P.Parameters, raw, "", problems)
    if not problems:
        problems += check_consistency(params)
    if problems:
        raise ScenarioError(problems, source=source)
    return params


# ----------------------------------------------------------------------------- overrides


def _apply_override(raw, item):
    if "\n" in item or "\r" in item:
        return [f"--set {item!r}: a line break inside one --set; give each key=value as its own --set"]
    if "=" not in item:
        return [f"--set {item!r}: expected key=value, e.g. integrator.dt=5e-4"]
    key, _, value_text = item.partition("=")
    key = key.strip()
    parts = key.split(".")
    if not key or any(not p for p in parts):
        return [f"--set {item!r}: the key must be a dotted path such as integrator.dt"]
    try:
        value = tomllib.loads(f"v = {value_text.strip()}")["v"]
    except tomllib.TOMLDecodeError:
        value = value_text.strip()
    except RecursionError:
        return [f"--set {key}: the value is nested too deeply"]
    except ValueError:  # e.g. an integer of more digits than Python converts
        return [f"--set {key}: the value {value_text.strip()[:40]!r}... is not a usable number"]
    node, tp = raw, P.Parameters
    for i, name in enumerate(parts[:-1]):
        tp = _field_type(tp, name)
        nxt = node.get(name)
        if nxt is None or isinstance(nxt, bool):  # a term on (true) or off (false): a key of it sets it on
            nxt = node[name] = {}
        elif _is_law(tp) and isinstance(nxt, (int, float)):  # a law given as a bare number: its table
            nxt = node[name] = {"distribution": "constant", "value": nxt}
        if not isinstance(nxt, dict):
            return [f"--set {item!r}: {'.'.join(parts[: i + 1])} is a value, not a table"]
        node = nxt
    if not (value is True and isinstance(node.get(parts[-1]), dict)):  # true keeps a term already on as it is
        node[parts[-1]] = value
    return []


# ----------------------------------------------------------------------------- schema walk


def _field_type(tp, name):
    """The type of field ``name`` of dataclass ``tp`` (Optional unwrapped), or None."""
    hint = typing.get_type_hints(tp).get(name) if dataclasses.is_dataclass(tp) else None
    return unwrap_optional(hint)[0] if hint is not None else None


def _is_law(tp) -> bool:
    """A per-rod law (charge, length, resistance): a bare number stands for the constant law."""
    return dataclasses.is_dataclass(tp) and "distribution" in fields_of(tp)


def unwrap_optional(tp):
    """``(T, True)`` for ``Optional[T]``, else ``(tp, False)``; shared with selfas_graph/bench/scenario_docs.py."""
    if typing.get_origin(tp) is typing.Union:
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        if len(args) == 1:
            return args[0], True
    return tp, False


def _build(cls, raw, prefix, problems):
    """Construct dataclass ``cls`` from dict ``raw``, appending problems; returns an instance or None."""
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls)}
    if not isinstance(raw, dict):
        problems.append(f"{prefix.rstrip('.') or 'scenario'}: expected a table, got {_describe(raw)}")
        return None
    for key in raw:
        if key not in fields:
            problems.append(_unknown_key(prefix + key, key, list(fields)))
    kwargs = {}
    for name, f in fields.items():
        if name not in raw:
            continue
        path = prefix + name
        tp, optional = unwrap_optional(hints[name])
        value = raw[name]
        if dataclasses.is_dataclass(tp):
            if optional and value is False:
                kwargs[name] = None
                continue
            if optional and value is True:
                value = {}
            if _is_law(tp) and isinstance(value, (int, float)) and not isinstance(value, bool):
                value = {"distribution": "constant", "value": value}  # a bare number: the same for every rod
            if optional and not isinstance(value, dict):
                # a section that may be off: say how (TOML's booleans are lower case; Python's False is a string)
                problems.append(
                    f"{path}: expected a table, or true / false to switch it on / off, got {_describe(value)}"
                )
                continue
            sub = _build(tp, value, path + ".", problems)
            if sub is not None:
                kwargs[name] = sub
            continue
        checked = _check_value(path, value, tp, f, problems)
        if checked is not _INVALID:
            kwargs[name] = checked
    try:
        if cls is P.Parameters:  # validated here and by check_consistency, not a second time
            P._unchecked.on = True
        return cls(**kwargs)
    except TypeError as exc:  # pragma: no cover - schema bug, not user error
        problems.append(f"{prefix or 'scenario'}: {exc}")
        return None
    finally:
        if cls is P.Parameters:
            P._unchecked.on = False


_INVALID = object()


def fields_of(cls):
    """Field names of dataclass ``cls``."""
    return [f.name for f in dataclasses.fields(cls)]


def _describe(value):
    """The value as the user wrote it (TOML spelling for booleans) and its type."""
    text = ("true" if value else "false") if isinstance(value, bool) else repr(value)
    if len(text) > 60:
        text = text[:57] + "..."
    return f"{text} ({type(value).__name__})"


def _resistance_spread(p):
    """(smallest, largest) resistance the circuit of ``p`` can hold: its rods' (``rods.resistance``,
    times the lengths where per unit length) and its contacts' (when not ideal)."""
    d = p.rods.resistance
    if d is None:
        lo = hi = 1.0
    elif d.distribution == "constant":
        lo = hi = d.value
    else:
        lo, hi = min(d.low, d.high), max(d.low, d.high)
    if d is not None and d.per_length and p.rods.length is not None:
        shortest, longest = p.rods.length.bounds()
        lo, hi = lo * shortest, hi * longest
    r = p.contacts.resistance
    if r > 0.0:
        lo, hi = min(lo, r), max(hi, r)
    return lo, hi


def _check_number(path, value, tp, meta, problems):
    if tp is bool:
        if not isinstance(value, (bool, np.bool_)):
            problems.append(f"{path}: expected true or false, got {_describe(value)}")
            return _INVALID
        return bool(value)  # numpy's booleans from Python callers become plain ones
    if tp is int:
        if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Integral):
            problems.append(f"{path}: expected an integer, got {_describe(value)}")
            return _INVALID
        value = int(value)  # numpy integers from Python callers become plain ones
    elif tp is float:
        try:
            value = as_decimal(value)  # a float32 is the decimal it prints as: np.float32(1e-3) is dt = 0.001
        except TypeError:
            problems.append(f"{path}: expected a number, got {_describe(value)}")
            return _INVALID
        if not math.isfinite(value):
            problems.append(f"{path}: expected a finite number, got {value}")
            return _INVALID
        if value != 0.0 and not MIN_MAGNITUDE <= abs(value) <= MAX_MAGNITUDE:
            problems.append(
                f"{path}: {value!r} is out of scale; every number of a scenario is 0 or between "
                f"{MIN_MAGNITUDE:g} and {MAX_MAGNITUDE:g} in magnitude (docs/model.md "
                f"'Reduced units'), so that the forces and energies derived from it stay finite"
            )
            return _INVALID
    elif tp is str:
        if not isinstance(value, str):
            problems.append(f"{path}: expected a string, got {_describe(value)}")
            return _INVALID
        choices = meta.get("choices")
        if choices and value not in choices:
            close = difflib.get_close_matches(value, choices, n=1)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            problems.append(f"{path}: {value!r} is not valid{hint}; valid: {', '.join(choices)}")
            return _INVALID
        return value
    bounds = []
    ok = True
    for key, op, word in (("ge", "__ge__", ">="), ("gt", "__gt__", ">"), ("le", "__le__", "<="), ("lt", "__lt__", "<")):
        b = meta.get(key)
        if b is not None:
            bounds.append(f"{word} {b:g}" if not isinstance(b, int) or abs(b) < 10**6 else f"{word} {b}")
            # integers compare exactly (2**63 is not <= 2**63 - 1, though their floats are equal)
            ok = ok and bool(getattr(value, op)(b) if tp is int else getattr(float(value), op)(float(b)))
    if not ok:
        problems.append(f"{path}: {value!r} is out of range; valid: {' and '.join(bounds)}")
        return _INVALID
    return value


def _check_value(path, value, tp, f, problems):
    meta = f.metadata
    if tp is tuple:
        template = f.default_factory() if f.default_factory is not dataclasses.MISSING else None
        return _check_array(path, value, template, problems)
    return _check_number(path, value, tp, meta, problems)


def _check_array(path, value, template, problems):
    """A fixed-shape array of numbers, shaped like the field's default (template)."""
    shape = _shape(template)
    want = "x".join(str(s) for s in shape)
    if not _has_shape(value, shape):
        problems.append(f"{path}: expected an array of {want} numbers, e.g. {_plain(template)}, got {_describe(value)}")
        return _INVALID
    try:
        flat = _flatten(value)
    except OverflowError:
        flat = [math.inf]
    if not all(math.isfinite(v) for v in flat):
        problems.append(f"{path}: every entry must be a finite number, got {_describe(value)}")
        return _INVALID
    if not all(v == 0.0 or MIN_MAGNITUDE <= abs(v) <= MAX_MAGNITUDE for v in flat):
        problems.append(
            f"{path}: an entry is out of scale; every number of a scenario is 0 or between "
            f"{MIN_MAGNITUDE:g} and {MAX_MAGNITUDE:g} in magnitude, got {_describe(value)}"
        )
        return _INVALID
    return _to_tuple(value)


def _shape(t):
    if isinstance(t, (list, tuple)):
        return (len(t),) + _shape(t[0])
    return ()


def _has_shape(value, shape):
    if not shape:
        return isinstance(value, (int, float)) and not isinstance(value, bool)
    return isinstance(value, list) and len(value) == shape[0] and all(_has_shape(v, shape[1:]) for v in value)


def _flatten(value):
    if isinstance(value, (list, tuple)):
        return [x for v in value for x in _flatten(v)]
    return [float(value)]


def _to_tuple(value):
    if isinstance(value, (list, tuple)):
        return tuple(_to_tuple(v) for v in value)
    return float(value)


def _plain(value):
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value


def _unknown_key(path, key, valid):
    close = difflib.get_close_matches(key, valid, n=1, cutoff=0.6)
    hint = f"; did you mean {close[0]!r}?" if close else ""
    return f"{path}: unknown key{hint} (valid keys here: {', '.join(valid)})"


# ----------------------------------------------------------------------------- cross-field checks


def check_consistency(p: P.Parameters):
    """Problems that involve several keys at once, in the order of the rules below; a box that cannot
    hold the rods stops the checks there (the rest would measure against it)."""
    out = _box_rules(p)
    if out:
        return out
    for rules in (_packing_rules, _rod_law_rules, _integrator_rules, _conductor_rules, _run_length_rules):
        out += rules(p)
    return out + _output_rules(p)


def _output_rules(p) -> list:
    """``output.file`` names a file (a trailing slash, dropped by the path, sent the run to a file)."""
    f = p.output.file
    if f and (f.endswith(("/", os.sep)) or Path(f).name in ("", ".", "..")):
        return [f"output.file: {f!r} names a folder, not a file; give a file name such as {f.rstrip('/')}/run.h5"]
    return []


def _box_rules(p) -> list:
    """The placement box: not empty, within +-1e6, large enough for the longest rod."""
    out = []
    rods, box = p.rods, p.placement.box
    for d, name in enumerate("xyz"):
        lo, hi = box[d]
        if not lo < hi:
            out.append(f"placement.box: the {name} range [{lo:g}, {hi:g}] is empty; write [low, high] with low < high")
    if out:
        return out
    # coordinates beyond 1e6 rod lengths overflow squared distances in the neighbour search
    # long before they mean anything physical
    if any(abs(v) > 1e6 for pair in box for v in pair):
        return out + ["placement.box: coordinates must lie within +-1e6 rod lengths"]
    ext = [box[d][1] - box[d][0] for d in range(3)]
    longest = rods.length.bounds()[1] if rods.length is not None else 1.0
    if rods.count > 0 and math.sqrt(sum(e * e for e in ext)) <= longest:
        out.append(
            f"placement.box: a rod of length {longest:g} cannot fit in a box of size "
            f"{ext[0]:g} x {ext[1]:g} x {ext[2]:g}; make the box larger"
        )
    return out


def _packing_rules(p) -> list:
    """Room in the box for the rods at their least tip distance."""
    out = []
    rods, box = p.rods, p.placement.box
    ext = [box[d][1] - box[d][0] for d in range(3)]
    dmin = p.min_tip_distance
    volume = ext[0] * ext[1] * ext[2]
    # random sequential packing of spheres jams near a volume fraction of 0.38;
    # beyond ~0.3 the rejection sampler stalls, so refuse that early and clearly
    fraction = 2 * rods.count * (math.pi / 6.0) * dmin**3 / volume
    if fraction > 0.3 and rods.count > 1:  # the distance is between tips of different rods: one rod always fits
        out.append(
            f"rods.count: {rods.count} rods cannot fit the box with placement.min_tip_distance = {dmin:g} "
            f"(exclusion volume fraction {fraction:.2f} > 0.3); use fewer rods, a larger box "
            f"or a smaller min_tip_distance"
        )
    return out


def _rod_law_rules(p) -> list:
    """The laws of the rods' charges, lengths and resistances."""
    out = []
    rods = p.rods
    for name, dist in (("magnetic_charge", rods.magnetic_charge), ("electric_charge", rods.electric_charge)):
        if dist.distribution == "magnetic" and name == "magnetic_charge":
            out.append(
                "rods.magnetic_charge.distribution: 'magnetic' is only valid for electric_charge; "
                "use constant, uniform or two_level"
            )
        if dist.distribution == "uniform" and dist.low > dist.high:
            out.append(f"rods.{name}: low = {dist.low:g} is above high = {dist.high:g}")
    for name in ("length", "resistance"):
        dist = getattr(rods, name)
        if dist is not None and dist.distribution == "uniform" and dist.low > dist.high:
            out.append(f"rods.{name}: low = {dist.low:g} is above high = {dist.high:g}")
    if rods.length is not None:
        mean = rods.length.mean()
        if abs(mean - 1.0) > 1e-9:
            out.append(
                f"rods.length: the law's mean is {mean:.12g}, not 1; lengths are in units of the mean rod "
                f"length L (docs/model.md 'Reduced units'), so choose values with mean 1 (e.g. uniform in "
                f"(0.5, 1.5))"
            )
        if rods.length.distribution == "two_level":
            # exactly high_count rods are long (the draw of model/placement.py): the mean of that draw
            m = high_count(rods.length, rods.count)
            drawn = ((rods.count - m) * rods.length.low + m * rods.length.high) / rods.count
            if abs(drawn - 1.0) > 0.01:
                out.append(
                    f"rods.length: {m} of {rods.count} rods get the high value (round(high_fraction * count)), so "
                    f"their mean is {drawn:.6g}, not 1 (more than 1 % off); choose a high_fraction and count whose "
                    f"product is near a whole number of rods"
                )
        shortest = rods.length.bounds()[0]
        if shortest < rods.diameter:
            out.append(
                f"rods.length: the shortest rod ({shortest:g}) is shorter than its diameter "
                f"rods.diameter = {rods.diameter:g}"
            )
    return out


def _integrator_rules(p) -> list:
    """The integrator's step counts against each other."""
    out = []
    ip = p.integrator
    # with slow_every = 1 every force is evaluated at every step and current_every has no effect
    if ip.current_every and ip.current_every % ip.slow_every:
        out.append(
            f"integrator.current_every: {ip.current_every} must be 0 (with the other slow forces) or a multiple of "
            f"integrator.slow_every = {ip.slow_every} (e.g. {2 * ip.slow_every})"
        )
    return out


def _conductor_rules(p) -> list:
    """The electrodes against the box, and what the circuit and the current terms need."""
    out = []
    box = p.placement.box
    el = p.forces.electrodes
    if el is not None:
        zlo, zhi = box[2]
        if zlo < -el.gap / 2 - 1e-12 or zhi > el.gap / 2 + 1e-12:
            out.append(
                f"placement.box: the z range [{zlo:g}, {zhi:g}] reaches beyond the electrodes at "
                f"z = +-{el.gap / 2:g} (forces.electrodes.gap = {el.gap:g}); rods must start between them"
            )
    if p.circuit is not None and el is None and p.forces.external_filament is None:
        out.append(
            "circuit: the circuit needs a conductor to apply its bias: add [forces.electrodes] (case (i)) "
            "or [forces.external_filament] (case (ii))"
        )
    if p.circuit is not None:
        spread = _resistance_spread(p)
        if spread[1] > MAX_RESISTANCE_SPREAD * spread[0]:
            out.append(
                f"contacts.resistance, rods.resistance: the circuit's resistances span {spread[0]:.3g} to "
                f"{spread[1]:.3g} R0, a factor above {MAX_RESISTANCE_SPREAD:.0e}: the Kirchhoff solve's round-off "
                f"grows with it and its currents would be wrong without a sign; keep them within that factor (or "
                f"contacts.resistance = 0, ideal contacts)"
            )
    if p.circuit is not None and not p.contacts.enabled:
        out.append(
            "circuit: the circuit is built from contacts; with contacts.enabled = false it can never close "
            "(remove [circuit] or enable contacts)"
        )
    for term in ("current_field", "current_lorentz"):
        if getattr(p.forces, term) is not None and p.circuit is None:
            out.append(
                f"forces.{term}: rod currents come from the circuit solve; add a [circuit] table "
                f"(with delta_J0) or remove this term"
            )
    return out


def _run_length_rules(p) -> list:
    """The run's and the frames' lengths against the time step."""
    out = []
    # a run of more than 1e12 steps cannot finish; its step count would also overflow
    for name, length in (("run.t_end", p.run.t_end), ("output.interval", p.output.interval)):
        if length / p.integrator.dt > 1e12:
            out.append(
                f"{name} / integrator.dt = {length / p.integrator.dt:.3g} steps; at most 1e12 are possible "
                f"(make integrator.dt larger or {name} smaller)"
            )
    for name, length in (("output.interval", p.output.interval), ("run.t_end", p.run.t_end)):
        if length < p.integrator.dt:  # a run.t_end below dt/2 took no step at all, and t_end > 0 was its rule
            out.append(f"{name} = {length:g} is shorter than integrator.dt = {p.integrator.dt:g}")
    return out
