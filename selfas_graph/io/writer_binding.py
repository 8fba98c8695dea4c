"""Which simulation a run file's writer takes frames from: :func:`check_simulation`, the part of
:meth:`RunWriter.check_continues <.run_writer.RunWriter.check_continues>` that tells one simulation from another.

A writer is bound to the simulation it was made for (:meth:`RunWriter.for_simulation`), by a weak reference,
and then to the last one it took frames from. Another simulation object is taken only as that one's exact
continuation (the same parameters apart from the end time, step and positions): a copy restored from its
snapshot. A writer with no simulation alive (:meth:`RunWriter.reopen`, or the one it was made for deleted)
takes one whose parameters are those the file states (apart from the end time), whose time follows the
file's last frame and, at that frame's step, whose positions are the frame's; then it is bound to it.
"""

from __future__ import annotations

import json
import math
import weakref

import numpy as np

from . import layout

#: the one parameter a continuation may change (``simulate --resume --t-end``, ``sim.run(t_end)``)
_FREE = ("run", "t_end")


def bind(writer, sim) -> None:
    """Make ``sim`` the simulation ``writer`` takes frames from."""
    writer._simulation = weakref.ref(sim)


def check_simulation(writer, sim) -> None:
    """ValueError, naming what differs, when ``sim`` is not the simulation ``writer`` takes frames from nor
    a continuation of it (module docstring); otherwise ``sim`` becomes that simulation."""
    bound = writer._simulation() if writer._simulation is not None else None
    if bound is sim:
        return
    if bound is not None:
        differs = parameter_differences(_plain(bound.params), _plain(sim.params), "the one it was made for", "this one")
        if not differs and bound.state.step != sim.state.step:
            differs = [f"the step is {bound.state.step} there and {sim.state.step} here"]
        if not differs and not np.array_equal(bound.state.position, sim.state.position):
            differs = [f"the positions at step {sim.state.step} differ"]
        if differs:
            raise ValueError(
                f"{writer.path}: this writer takes the frames of another simulation ({'; '.join(differs)}); {_WAY_ON}"
            )
    else:
        differs = parameter_differences(_file_parameters(writer), _plain(sim.params), "the file", "the simulation")
        differs += _frame_differences(writer, sim)
        if differs:
            raise ValueError(
                f"{writer.path}: the simulation does not continue this file ({'; '.join(differs)}); {_WAY_ON}"
            )
    bind(writer, sim)


_WAY_ON = (
    "a writer takes the frames of the simulation it was made for and its continuation: RunWriter.for_simulation"
    "(sim, path) for a new file, RunWriter.reopen(path, sim.state.step) for a simulation restored from this run"
)


def parameter_differences(theirs: dict, ours: dict, where: str, here: str, path=()) -> list[str]:
    """The parameters (dotted keys) whose values differ between ``theirs`` (those of ``where``) and ``ours``
    (those of ``here``), the end time aside; a key one of them lacks (a file of an older version) is not
    compared."""
    out = []
    for key in theirs.keys() & ours.keys():
        a, b, name = theirs[key], ours[key], path + (key,)
        if name == _FREE:
            continue
        if isinstance(a, dict) and isinstance(b, dict):
            out += parameter_differences(a, b, where, here, name)
        elif a != b:
            out.append(f"{'.'.join(name)} is {a!r} in {where} and {b!r} in {here}")
    return sorted(out)


def _plain(params) -> dict:
    """``params`` as the file stores them (JSON: tuples as lists)."""
    return json.loads(json.dumps(params.to_dict()))


def _file_parameters(writer) -> dict:
    text = writer.f[layout.PROVENANCE].attrs.get("parameters_json")
    return json.loads(text) if text else {}


def _frame_differences(writer, sim) -> list[str]:
    """How ``sim``'s time and positions fail to follow the file's last frame (none: they follow it)."""
    steps = writer._elements["position"][0]
    if not steps.shape[0]:
        return []
    step, st = int(steps[-1]), sim.state
    t = float(writer._elements["position"][1][-1]) + (st.step - step) * sim.dt
    if not math.isclose(st.time, t, rel_tol=1e-9, abs_tol=1e-12):
        return [f"its time {st.time!r} at step {st.step} does not follow the last frame's, t = {t!r} at that step"]
    if st.step == step and not np.array_equal(writer._elements["position"][2][-1], st.position):
        return [f"its positions at step {step} are not those of the file's last frame"]
    return []
