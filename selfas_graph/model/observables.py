"""What a simulation reports about its state: energies, observables (one row per saved frame),
the status a progress display shows, the contact count.

:class:`Observables` is a component of :class:`~.simulation.Simulation` (``sim.observe``), built
with the parts it reads: the state, the force field, the integrator and the network. What the
simulation keeps of the run (its events, the time of the first short circuit) comes in as arguments.
"""

from __future__ import annotations

import numpy as np

from ..kernels.contacts import close_pair_count
from . import events as ev

#: the electrodes of case (i), whose contacts the status counts together
ELECTRODES = (ev.CONDUCTOR_CATHODE, ev.CONDUCTOR_ANODE)


def energy_scale(obs) -> float:
    """Energy turned over so far: kinetic energy plus |work| of every non-conservative channel of
    the observables ``obs``."""
    return abs(obs["energy/kinetic"]) + sum(abs(v) for k, v in obs.items() if k.startswith("work/"))


class Observables:
    """The measures a simulation gives of its present state.

    Parameters
    ----------
    params : Parameters
    state : State
        Advanced in place by the integrator (the same object all run long).
    force_field : ForceField
    integrator : AdamsBashforth4
        Its work per non-conservative channel and its bond error.
    network : Network or None
        Contacts, topology and circuit solution (None when contacts are off).

    Attributes
    ----------
    energy0 : float or None
        E(0) - W(0), the reference of the energy balance (None until taken).
    """

    def __init__(self, params, state, force_field, integrator, network):
        self.params = params
        self.state = state
        self.force_field = force_field
        self.integrator = integrator
        self.network = network
        self.energy0 = None

    def energies(self) -> dict:
        """Kinetic and potential energy of each conservative term (unit tip masses).

        Taken at a step of the frame grid (a multiple of ``output.interval`` in whole steps) the energy
        updates the neighbour lists as a step would, as the runs always have (their trajectories depend
        on the frame interval; docs/output.md); taken elsewhere (the end of a run or of a chunk off the
        grid, a call from Python) it reads them without moving their rebuilds, so that where a run stops
        does not change its trajectory."""
        from .operations import frame_steps  # operations -> health -> this module

        st = self.state
        on_grid = st.step % frame_steps(self.params.output.interval, self.integrator.dt) == 0
        e = {"kinetic": 0.5 * float(np.einsum("ij,ij->", st.velocity, st.velocity))}
        e.update(self.force_field.potential_energy(st.position, keep_lists=not on_grid))
        return e

    def record_initial_energy(self):
        """E(0) - W(0), the reference of the energy balance, taken before the first step."""
        self.energy0 = sum(self.energies().values()) - float(self.integrator.work.sum())

    def observables(self, n_events: int = 0) -> dict:
        """Scalars and small vectors describing the current state (one row per saved frame);
        ``n_events`` is the number of events so far (saved as ``events`` with a network)."""
        st = self.state
        obs = {}
        energy = self.energies()
        for k, v in energy.items():
            obs[f"energy/{k}"] = v
        total = sum(energy.values())
        work = dict(zip(self.force_field.nonconservative, self.integrator.work))
        for k, w in work.items():
            obs[f"work/{k}"] = w
        if self.energy0 is None:
            self.energy0 = total - sum(work.values())
        # E(t) - E(0) - W(t): zero up to the integration error (docs/model.md 'Work bookkeeping and the energy balance': brakes
        # and the plasma field do work, tracked per channel by the integrator)
        obs["energy_total"] = total
        obs["energy_balance"] = total - sum(work.values()) - self.energy0
        obs["momentum"] = st.velocity.sum(axis=0)
        obs["bond_error"] = self.integrator.bond_error_before
        obs["contacts"] = float(self.contact_count())
        if self.network is not None:
            topo = self.network.topology()
            obs["rods/filament"] = topo.n_filament
            obs["rods/dead_end"] = topo.n_dead_end
            obs["rods/cluster"] = topo.n_cluster
            obs["rods/free"] = topo.n_free
            obs["largest_structure"] = (
                int(topo.structure_size[topo.largest_structure]) if topo.largest_structure >= 0 else 0
            )
            obs["events"] = n_events
            obs["short_circuit"] = float(topo.has_short_circuit)
        if self.params.circuit is not None:
            sol = self.network.solution if self.network is not None else None
            obs["total_current"] = sol.total_current if sol is not None else 0.0
            # the conductance, not the resistance: an open circuit's is 0, a finite number (files hold no inf)
            r = sol.effective_resistance if sol is not None else float("inf")
            obs["effective_conductance"] = 1.0 / r if 0.0 < r < float("inf") else 0.0
        return obs

    def status(self, short_circuit_time=None) -> dict:
        """What a progress display shows: tip contacts, tip-conductor contacts (electrodes, the
        case (ii) filament), the time of the first short circuit (``short_circuit_time``, None
        before it), the total current (J0) and the number of rods carrying current."""
        net = self.network
        c = net.contacts if net is not None else None
        sol = net.solution if net is not None else None
        return {
            "contacts": self.contact_count(),
            "electrode_contacts": int(np.isin(c.conductor_id, ELECTRODES).sum()) if c is not None else 0,
            "filament_contacts": int((c.conductor_id == ev.CONDUCTOR_FILAMENT).sum()) if c is not None else 0,
            "short_circuit_time": short_circuit_time,
            "total_current": float(sol.total_current) if sol is not None else 0.0,
            "current_rods": int(np.count_nonzero(self.force_field.current)),
        }

    def contact_count(self) -> int:
        """Number of tip pairs of different rods in contact (closer than r*, or still held by hysteresis)."""
        if self.network is not None:
            return self.network.contacts.n_contacts
        tnl = self.force_field.tip_neighbours(self.state.position)
        return int(close_pair_count(self.state.position, tnl.start, tnl.index, self.params.rods.rstar))
