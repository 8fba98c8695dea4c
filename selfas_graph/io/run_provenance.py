"""What a run file records about its run (``/parameters/selfas_graph``, :mod:`selfas_graph.io.h5md`):
:func:`run_provenance`."""

from __future__ import annotations

import json


def run_provenance(sim, scenario, command_line, run_id, scenario_path=None, mpi_ranks=1) -> dict:
    """The attributes of ``/parameters/selfas_graph`` of a run file: the scenario text, path and
    overrides (a placeholder for a scene built in Python), the resolved and derived parameters,
    the version, the command, the seed, the ranks and threads and the run identity."""
    import numba

    from .._version import __version__
    from ..provenance import cpu_model, numba_target, source_commit

    p = sim.params
    target = numba_target()
    if scenario_path is None:
        scenario_path = scenario.path if scenario is not None and scenario.path is not None else ""
    return {
        "scenario_text": scenario.text
        if scenario is not None
        else "# built in Python; the resolved parameters are in parameters_json\n",
        "scenario_path": str(scenario_path),
        "overrides": json.dumps(list(scenario.overrides) if scenario is not None else []),
        "parameters_json": json.dumps(p.to_dict()),
        "derived_json": json.dumps(sim.force_field.describe()),
        "version": __version__,
        "command_line": command_line,
        "seed": p.scenario.seed,
        "mpi_ranks": int(mpi_ranks),
        "numba_threads": numba.get_num_threads(),
        "run_id": str(run_id),
        "commit": source_commit(),
        "cpu_model": cpu_model(),
        "numba_cpu": f"{target['cpu_name']} ({target['widest']})",
    }
