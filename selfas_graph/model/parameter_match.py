"""Whether a file's stored parameters are those of a simulation: :func:`parameter_differences`, the one rule
of a seed file of an ensemble (``ensemble/plan.py``), of a run file a resume continues
(``lifecycle.continuation``) and of a run file a simulation continues from Python (``io/writer_binding.py``).
Keys added by later versions count at their defaults."""

from __future__ import annotations

import dataclasses
import functools
import json
import types
import typing

#: parameters a file may differ in and still be the simulation's (a seed of the ensemble, a run continued)
FREE_PARAMETERS = ("run.t_end", "output.file", "output.checkpoint_interval")


def _flat(d, prefix=""):
    out = {}
    for k, v in d.items():
        key = f"{prefix}{k}"
        if isinstance(v, dict) and v:
            out.update(_flat(v, key + "."))
        else:
            out[key] = v
    return out


def parameter_differences(stored: dict, wanted: dict) -> list[str]:
    """Dotted keys whose values differ between ``stored`` (a file's parameters, JSON) and ``wanted`` (a
    simulation's, ``Parameters.to_dict()``), except :data:`FREE_PARAMETERS` and a key ``stored`` lacks
    whose wanted value is its default."""
    a, b = _flat(json.loads(json.dumps(stored))), _flat(json.loads(json.dumps(wanted)))
    return sorted(
        k
        for k in set(a) | set(b)
        if k not in FREE_PARAMETERS and a.get(k) != b.get(k) and not _newer_key_at_default(k, a, b)
    )


def described_differences(stored: dict, wanted: dict, where: str, here: str) -> list[str]:
    """:func:`parameter_differences` as sentences: "key is <stored value> in ``where`` and <wanted> in ``here``"."""
    wanted = json.loads(json.dumps(wanted))
    return [
        f"{k} is {value_at(stored, k)!r} in {where} and {value_at(wanted, k)!r} in {here}"
        for k in parameter_differences(stored, wanted)
    ]


def _newer_key_at_default(key, stored_flat, wanted_flat) -> bool:
    """True for a key that a file of an earlier version lacks (the key came later) while the
    wanted value is that key's default: the run used what the default means. A key of a force
    term counts only where the stored file has that term on (an absent term is off)."""
    if key in stored_flat or key not in wanted_flat:
        return False
    if key.startswith("forces."):
        term = ".".join(key.split(".")[:2]) + "."
        if not any(k.startswith(term) for k in stored_flat):
            return False
    return _DEFAULTS_FLAT().get(key, _MISSING) == wanted_flat[key]


_MISSING = object()


@functools.lru_cache(maxsize=1)
def _DEFAULTS_FLAT():
    """Every key's default, dotted, including the keys of the optional tables (force terms,
    ``[circuit]`` ...) that are off by default: a key added to such a table later has a default
    too, and a file of an earlier version that has the table on used it."""
    from .params import Parameters

    flat = _flat(json.loads(json.dumps(Parameters().to_dict())))
    flat.update(_optional_table_defaults(Parameters, ""))
    return flat


def _optional_table_defaults(cls, prefix) -> dict:
    """Dotted defaults of the keys of every optional table below the dataclass ``cls``."""
    out = {}
    hints = typing.get_type_hints(cls)
    for f in dataclasses.fields(cls):
        tp = hints[f.name]
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        inner = args[0] if typing.get_origin(tp) in (typing.Union, types.UnionType) and len(args) == 1 else tp
        if not dataclasses.is_dataclass(inner):
            continue
        key = f"{prefix}{f.name}"
        if inner is not tp:  # optional: off by default, its keys' defaults from the table's class
            try:
                table = inner()
            except TypeError:  # a table without defaults for every key has no default to offer
                continue
            for k, v in _flat(json.loads(json.dumps(dataclasses.asdict(table)))).items():
                out[f"{key}.{k}"] = v
        out.update(_optional_table_defaults(inner, key + "."))
    return out


def value_at(d, dotted):
    """The value of the dotted key ``dotted`` in the nested dict ``d`` (None where it has none)."""
    for k in dotted.split("."):
        if not isinstance(d, dict) or k not in d:
            return None
        d = d[k]
    return d
