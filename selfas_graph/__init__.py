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

import importlib

from ._version import __version__

#: where each name of the API lives; imported on first use (PEP 562), so that the command line
#: imports numba, scipy, h5py and networkx inside its own handling of a Ctrl-C (cli/main.py::main)
_API = {
    ".io.export": ("ExportError", "export_run"),
    ".io.h5md": ("RunFile", "RunFileError", "RunWriter"),
    ".io.scenario": ("Scenario", "ScenarioError", "load_scenario", "parameters_from_dict", "scenario_from_text"),
    ".model.circuit": ("CircuitSolution", "solve_circuit"),
    ".model.events": ("Event", "EventKind", "named_events"),
    ".model.graph": ("ROLE_NAMES", "ConnectivityGraph", "classify_rods"),
    ".model.network": ("Network",),
    ".model.operations": ("Operation", "Periodic", "Always", "When", "RunInterrupted"),
    ".model.params": ("Parameters",),
    ".model.simulation": ("NumericalFailure", "RunSummary", "Simulation"),
    ".model.placement": ("PlacementError", "random_state"),
    ".model.state": ("State", "StateError"),
}
#: the subpackages and modules, reachable as attributes once the API is imported (as they were when it
#: was imported with the package)
_PACKAGES = ("analysis", "bench", "cli", "ensemble", "grid", "io", "kernels", "lifecycle", "model", "parallel")
_PACKAGES += ("provenance", "studies")
_HOME = {name: module for module, names in _API.items() for name in names}


def __getattr__(name):
    module = _HOME.get(name)
    if module is None and name in _PACKAGES:  # e.g. selfas_graph.model.state.State
        for module in _API:
            importlib.import_module(module, __name__)
        return importlib.import_module(f".{name}", __name__)
    if module is None:
        raise AttributeError(f"module 'selfas_graph' has no attribute {name!r}")
    value = getattr(importlib.import_module(module, __name__), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(_HOME))


__all__ = ["__version__", *_HOME]
