"""A scene built in Python, without a scenario file: run in chunks, read roles, currents, events.

Three rods stand in a column between two electrodes, their tips touching, so the electrodes
are short-circuited from the first step; six free rods float beside them. The script

1. makes validated parameters from a dict and changes them with ``replace``,
2. builds the state from rod centres and axes (``State.from_rods``),
3. runs in chunks, writing a run file, and prints roles, currents and events as it goes,
4. reads the file back with ``RunFile``.

Run it with ``python examples/python_api.py [OUT.h5]`` (a few seconds after the kernels are
compiled; an existing OUT.h5 is refused, as ``simulate`` refuses it without ``--force``); the tests
run it too (tests/cli/test_python_api.py).
"""

import sys
import tempfile
from pathlib import Path

import numpy as np

import selfas_graph as sg

# 1. parameters: a nested dict as a scenario file would hold, validated the same way
params = sg.Parameters.from_dict(
    {
        "scenario": {"name": "column", "seed": 7},
        "rods": {"count": 9},
        "placement": {"box": [[-3.0, 3.0], [-3.0, 3.0], [-1.5, 1.5]]},
        "forces": {"tip_magnetic": {}, "tip_brake": {}, "ambient_brake": {}, "electrodes": {"gap": 3.06}},
        "circuit": {"delta_J0": 2.0},
        "output": {"interval": 0.05},
    }
)
params = params.replace({"integrator.dt": 1e-3}, forces={"uniform_field": {"B": [0.0, 0.0, 0.5]}})
try:
    params.replace(integrator={"dt": -1.0})
except sg.ScenarioError as exc:  # the message a scenario file with dt = -1 gets
    print(f"refused: {exc.problems[0]}")

# 2. the state: a column of three vertical rods whose tips are 0.02 apart (closer than r* = 0.06)
#    and 0.02 from the electrodes at z = +-1.53, and six free rods around it
column = np.array([[0.0, 0.0, -1.02], [0.0, 0.0, 0.0], [0.0, 0.0, 1.02]])
free = np.array([[2.0 * np.cos(a), 2.0 * np.sin(a), 0.0] for a in np.linspace(0, 2 * np.pi, 6, endpoint=False)])
centre = np.vstack([column, free])
axis = np.vstack([np.tile([0.0, 0.0, 1.0], (3, 1)), np.tile([1.0, 0.0, 0.0], (6, 1))])
q = np.full(9, 1.0)  # magnetic charge of each rod: +q on tip 2i, -q on tip 2i+1
state = sg.State.from_rods(centre, axis, magnetic_charge=q, electric_charge=q)

sim = sg.Simulation(params, state=state)  # validates and copies the state
print(f"t = 0: short circuit at t = {sim.short_circuit_time}")

# 3. run in chunks, writing a run file
out = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(tempfile.mkdtemp()) / "column.h5"
with sg.RunWriter.for_simulation(sim, out) as writer:  # OutputExistsError if out exists
    for t_end in (0.1, 0.2, 0.3):
        sim.run(t_end, writer=writer)
        role = sim.network.topology().role
        names = [sg.ROLE_NAMES[int(r)] for r in role]
        current = sim.force_field.current
        print(
            f"t = {sim.state.time:.3f}: roles {names[:3]} (column), {names[3]} (free); "
            f"currents in the column {np.round(current[:3], 4).tolist()}, "
            f"total {sim.observables()['total_current']:.4f}"
        )

# events by name
for event in sg.named_events(sim.events)[:5]:
    print(f"  step {event.step}: {event.kind.label} ({event.a}, {event.b})")
assert any(e.kind == sg.EventKind.SHORT_CIRCUIT for e in sg.named_events(sim.events))

# 4. read the file back
with sg.RunFile(out) as run:
    g = run.graph(frame=-1)
    print(
        f"{out}: {run.n_frames} frames; last frame roles {np.bincount(g['role'], minlength=4).tolist()} "
        f"(free, cluster, dead_end, filament); {len(run.named_events())} events, first "
        f"{run.named_events()[0].kind.label}"
    )
