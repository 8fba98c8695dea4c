"""One saved frame of a run file: :class:`SavedFrame`, made by :meth:`RunFile.frame`.

The frame's positions, step and time, the graph data saved at the same step (if any), the
topology rebuilt from its contacts (``model.graph.ConnectivityGraph``), and the facts of the
scene it was run in (gap, dipole, plasma filament). Everything but the step and time is read
on first use. Measures over a frame (``analysis/``) take these arrays; ``ensemble.Frame`` adds
its cached measures on top.
"""

from __future__ import annotations

import functools

import numpy as np

from ..model.graph import ConnectivityGraph


class SavedFrame:
    """One saved frame of an open run file.

    Parameters
    ----------
    run : RunFile
    index : int
        The frame's index in the file, 0 <= index < run.n_frames (:meth:`RunFile.frame` checks it).
    params : dict, optional
        The run's stored parameters (``run.parameters``), when the caller holds them already.

    Attributes
    ----------
    run, index, time, step
    position : (n_tips, 3) float64
    n_rods : int
    params : dict, the run's resolved parameters
    graph : dict or None
        :meth:`RunFile.graph` of the same step, None when no graph data were saved with the frame.
    topology : model.topology.Topology or None
        Structures and roles rebuilt from the saved contacts by the current topology rule.
    role, structure : (n_rods,) int, or None without graph data
    largest_mask : (n_rods,) bool, the rods of the largest structure
    wire_radius : float, half the rods' diameter (L)
    gap : float or None, the electrodes' gap (case (i))
    dipole : (Z_Mext, L_ext) or None, the external dipole (case (ii))
    external_filament : bool, whether the scene has the fixed current filament (case (ii))
    plasma : dict or None, the plasma filament's table (``axis``, ``radius``, ...)
    """

    def __init__(self, run, index, params=None):
        self.run, self.index = run, int(index)
        self.time = float(run.time[self.index])
        self.step = int(run.step[self.index])
        if params is not None:
            self.params = params

    @functools.cached_property
    def params(self) -> dict:
        return self.run.parameters

    @functools.cached_property
    def position(self) -> np.ndarray:
        return self.run.position(self.index)

    @property
    def n_rods(self) -> int:
        return self.run.n_tips // 2

    @functools.cached_property
    def graph(self):
        record = self.run.graph_record_of_step(self.step)
        return None if record is None else self.run.graph(frame=record)

    def require_graph(self, kind: str) -> dict:
        """The frame's graph data, or a :class:`RunFileError` naming what the ``kind`` of output needs."""
        from .h5md import RunFileError

        if self.graph is None:
            if not self.run.has_graph:
                self.run.graph_frame_index(self.index)  # raises the reader's explanation
            raise RunFileError(
                f"{self.run.path}: no graph data saved at frame {self.index} (step {self.step}), "
                f"which the {kind} plot needs"
            )
        return self.graph

    @functools.cached_property
    def topology(self):
        if self.graph is None:
            return None
        r = self.run.contact_resistance  # resistive contacts merge no tips (docs/model.md 'Circuit')
        graph = ConnectivityGraph.from_arrays(self.n_rods, self.graph["conductors"], self.graph, contact_resistance=r)
        return graph.topology()

    @property
    def role(self):
        return None if self.topology is None else self.topology.role

    @property
    def structure(self):
        return None if self.topology is None else self.topology.structure

    @property
    def largest_mask(self) -> np.ndarray:
        topo = self.topology
        if topo is None or topo.largest_structure < 0:
            return np.zeros(self.n_rods, dtype=bool)
        return topo.structure == topo.largest_structure

    # ------------------------------------------------------------------ the scene
    @property
    def _forces(self) -> dict:
        return self.params.get("forces") or {}

    @property
    def wire_radius(self) -> float:
        return 0.5 * float(self.params["rods"]["diameter"])

    @property
    def gap(self):
        electrodes = self._forces.get("electrodes")
        return float(electrodes["gap"]) if electrodes else None

    @property
    def dipole(self):
        """Case (ii): (Z_Mext, L_ext) of the external dipole, None without one."""
        dipole = self._forces.get("external_dipole")
        return (float(dipole["magnetic_charge"]), float(dipole["length"])) if dipole else None

    @property
    def external_filament(self) -> bool:
        return self._forces.get("external_filament") is not None

    @property
    def plasma(self):
        return self._forces.get("plasma_filament")
