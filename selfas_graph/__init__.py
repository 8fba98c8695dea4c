"""selfas-graph: electrodynamic aggregation of magnetized nanodust (after SELFAS-3).

The Python API a script or notebook uses::

    import selfas_graph as sg
    scenario = sg.load_scenario("scenarios/quick.toml", overrides=["integrator.dt=5e-4"])
    sim = sg.Simulation.from_scenario(scenario)
    summary = sim.run(t_end=2.0)
    with sg.RunFile("quick.h5") as run:      # results of a CLI run
        run.position(frame=-1)

    params = sg.Parameters().replace(rods={"count": 50})   # validated as a scenario file is
    sim = sg.Simulation(params)
    with sg.RunWriter.for_simulation(sim, "mine.h5") as out:
        sim.run(1.0, writer=out)                             # in chunks: run(1.0), run(2.0), ...
    sim.operations.append(my_operation)   # an sg.Operation with a trigger, e.g. sg.Periodic(100)

A worked example: examples/python_api.py.

Layers: :mod:`selfas_graph.kernels` (numba, arrays only), :mod:`selfas_graph.model`
(state, forces, integrator, network: contacts, graph, circuit; operations), and the edges
:mod:`selfas_graph.io` (scenarios, HDF5), :mod:`selfas_graph.cli`,
:mod:`selfas_graph.parallel` (MPI).
"""

from ._version import __version__
from .io.export import ExportError, export_run
from .io.h5md import RunFile, RunFileError, RunWriter
from .io.scenario import Scenario, ScenarioError, load_scenario, parameters_from_dict, scenario_from_text
from .model.circuit import CircuitSolution, solve_circuit
from .model.events import Event, EventKind, named_events
from .model.graph import ROLE_NAMES, ConnectivityGraph, classify_rods
from .model.network import Network
from .model.operations import Operation, Periodic
from .model.params import Parameters
from .model.simulation import NumericalFailure, RunSummary, Simulation
from .model.state import PlacementError, State, StateError, random_state

__all__ = [
    "__version__",
    "load_scenario",
    "scenario_from_text",
    "parameters_from_dict",
    "Scenario",
    "ScenarioError",
    "Parameters",
    "Simulation",
    "RunSummary",
    "NumericalFailure",
    "State",
    "StateError",
    "random_state",
    "PlacementError",
    "RunFile",
    "RunFileError",
    "RunWriter",
    "export_run",
    "ExportError",
    "solve_circuit",
    "CircuitSolution",
    "ConnectivityGraph",
    "classify_rods",
    "ROLE_NAMES",
    "Event",
    "EventKind",
    "named_events",
    "Network",
    "Operation",
    "Periodic",
]
