"""io/layout.py's names against what the writer makes: a dataset the writer adds to a group but the
lists leave out would be left uncut when a resume trims the file (io/trim.py), its column then longer
than the others."""

import h5py

import selfas_graph as sg
from selfas_graph.io import layout
from selfas_graph.model.circuitlog import CIRCUIT_LOG_DTYPE


def _run_file(path):
    params = sg.Parameters.from_dict(
        {
            "rods": {"count": 3},
            "placement": {"box": [[-3, 3], [-3, 3], [-1.5, 1.5]]},
            "forces": {"tip_magnetic": {}, "electrodes": {"gap": 3.06}},
            "circuit": {"delta_J0": 2.0},
            "output": {"interval": 0.05},
        }
    )
    state = sg.State.from_rods([[0, 0, -1.02], [0, 0, 0], [0, 0, 1.02]], [[0, 0, 1]] * 3, 1.0, 1.0)
    sim = sg.Simulation(params, state=state)
    with sg.RunWriter.for_simulation(sim, path) as w:
        sim.run(0.1, writer=w)


def test_every_dataset_of_the_graph_and_the_circuit_log_is_one_the_trim_cuts(tmp_path):
    _run_file(tmp_path / "r.h5")
    with h5py.File(tmp_path / "r.h5", "r") as f:
        graph = set(f[layout.GRAPH])
        circuit_log = set(f[layout.CIRCUIT_LOG])
        assert len(f[layout.GRAPH]["step"]) == 3 and len(f[layout.CIRCUIT_LOG]["step"]) > 0
    cut = set(layout.GRAPH_PER_FRAME) | {layout.GRAPH_FLOATING, "tip_contacts"} | set(layout.GRAPH_CONDUCTOR_CONTACTS)
    assert graph == cut
    assert set(layout.GRAPH_DATASETS) <= graph
    assert circuit_log == set(layout.CIRCUIT_LOG_COLUMNS)
    assert layout.CIRCUIT_LOG_COLUMNS == CIRCUIT_LOG_DTYPE.names
