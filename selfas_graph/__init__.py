"""selfas-graph: electrodynamic aggregation of magnetized nanodust (after SELFAS-3).

The Python API a script or notebook uses::

    import selfas_graph as sg
    scenario = sg.load_scenario("scenarios/quick.toml", overrides=["integrator.dt=5e-4"])
    sim = sg.Simulation.from_scenario(scenario)
    summary = sim.run(t_end=2.0)
    with sg.RunFile("quick.h5") as run:      # results of a CLI run
        run.position(frame=-1)

Layers: :mod:`selfas_graph.kernels` (numba, arrays only), :mod:`selfas_graph.model`
(state, forces, integrator, events, graph, circuit), and the edges
:mod:`selfas_graph.io` (scenarios, HDF5), :mod:`selfas_graph.cli`,
:mod:`selfas_graph.parallel` (MPI).
"""
from ._version import __version__
from .io.h5md import RunFile, RunFileError
from .io.scenario import Scenario, ScenarioError, load_scenario, scenario_from_text
from .model.params import Parameters
from .model.simulation import NumericalFailure, RunSummary, Simulation
from .model.state import PlacementError, State, random_state

__all__ = [
    "__version__", "load_scenario", "scenario_from_text", "Scenario", "ScenarioError", "Parameters",
    "Simulation", "RunSummary", "NumericalFailure", "State", "random_state", "PlacementError",
    "RunFile", "RunFileError",
]
