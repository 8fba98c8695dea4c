"""Which simulation a run file's writer takes frames from: :func:`check_simulation`, the part of
:meth:`RunWriter.check_continues <.run_writer.RunWriter.check_continues>` that tells one simulation from another.

The rule is read from what the writer has written, not from a simulation object: a simulation is taken when
its parameters are those the file states (the end time, output file and checkpoint interval aside:
:func:`~selfas_graph.model.parameter_match.parameter_differences`), its step is not before the last step
written (the last frame's or per-step row's; a reopened file's, the step it was reopened at), it holds at
least the events and circuit-log rows written, its time follows the last frame's and, at that frame's step,
its positions are the frame's. A copy restored from the simulation's snapshot at the file's last frame is
taken; one restored from an earlier state (``sim.last_good_snapshot`` after a Ctrl-C) is refused, whose
rows the file holds already. The simulation last taken, held by a weak reference, is taken without a look.
This guards runs from Python: ``simulate --resume`` and an ensemble's resume check the file's parameters
before it is reopened (``lifecycle.continuation``), on every MPI rank.
"""

from __future__ import annotations

import json
import math
import weakref

import numpy as np

from ..model.parameter_match import described_differences
from . import layout


def bind(writer, sim) -> None:
    """Make ``sim`` the simulation ``writer`` takes frames from."""
    writer._simulation = weakref.ref(sim)


def check_simulation(writer, sim) -> None:
    """ValueError, naming what differs, when ``sim`` does not continue what ``writer`` has written (module
    docstring); otherwise ``sim`` becomes the simulation it takes frames from."""
    bound = writer._simulation() if writer._simulation is not None else None
    if bound is sim:
        return
    differs = described_differences(_file_parameters(writer), sim.params.to_dict(), "the file", "the simulation")
    differs += _written_differences(writer, sim) or _frame_differences(writer, sim)
    if differs:
        raise ValueError(f"{writer.path}: the simulation does not continue this file ({'; '.join(differs)}); {_WAY_ON}")
    bind(writer, sim)


_WAY_ON = (
    "a writer takes the frames of the simulation it was made for and of its continuation: RunWriter.for_simulation"
    "(sim, path) for a new file; to continue the file from an earlier state, close the writer and "
    "RunWriter.reopen(path, sim.state.step, drop_later=True)"
)


def _file_parameters(writer) -> dict:
    text = writer.f[layout.PROVENANCE].attrs.get("parameters_json")
    return json.loads(text) if text else {}


def last_step_written(writer) -> int | None:
    """The step the file continues after: a reopened file's own (``RunWriter.reopen``) until a run continues
    it, else the later of its last frame's step and its last per-step row's (None: nothing written)."""
    if writer._continues_from is not None:
        return writer._continues_from
    steps = [int(ds[-1]) for ds in (writer._elements["position"][0], writer._per_step[0]) if ds.shape[0]]
    if writer._n_pending:
        steps.append(int(writer._pending[0][writer._n_pending - 1]))
    return max(steps) if steps else None


def _written_differences(writer, sim) -> list[str]:
    """How ``sim`` falls short of what the file holds: a step before the last written, fewer events or
    circuit-log rows than written (none: it does not)."""
    st, last = sim.state, last_step_written(writer)
    if last is not None and st.step < last:
        return [f"its step {st.step} is before the last step the file holds, {last}"]
    out = []
    for what, have, written in (
        ("events", len(sim.events), writer.events_written),
        ("circuit-log rows", len(sim.circuit_log), writer.circuit_rows_written),
    ):
        if have < written:
            out.append(f"it holds {have} {what}, the file {written}")
    return out


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
