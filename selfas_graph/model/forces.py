"""The force field: which terms of docs/model.md 'Force terms' are on, and how each is computed.

A :class:`ForceField` is built from the scenario's ``[forces]`` tables; only
the listed terms are constructed, so a term the scene does not use costs
nothing (no buffer, no kernel call, no neighbour list). Each term writes its
force into its own *channel* buffer; the field sums the channels and, for the
non-conservative channels, the power ``sum_k F_k . v_k`` that the integrator
turns into work. Conservative channels report a potential energy instead.

The expensive terms (tip-tip sum, Yukawa, the two current terms) compute only the
rows of the field's :class:`~selfas_graph.parallel.RowBlocks` block of rods and say
so through :meth:`_Term.blocked`; :meth:`ForceField.evaluate` then fills in the other
ranks' rows, so every channel is complete on every rank. With one rank the block
is every rod and nothing is communicated. Their energies are computed as one value
per row, gathered the same way and summed over all rows on every rank: the same
float whatever the number of ranks.
"""
from __future__ import annotations

import math
import time
from collections import Counter

import numpy as np

from ..kernels import currents as kc
from ..kernels import external as kx
from ..kernels import fields as kf
from ..kernels import pairs as kp
from ..kernels import tips as kt
from ..kernels import tree as ktree
from ..parallel import RowBlocks
from .neighbours import NeighbourList
from .params import Parameters


def yukawa_cutoff(z_max: float, screening: float, tolerance: float) -> float:
    """Distance beyond which ``z_max^2 exp(-r/R_D) (1/r^2 + 1/(R_D r)) < tolerance``.

    The force magnitude decreases monotonically in r, so bisection on
    ``[1e-6, 1e6]`` finds the crossing to 1e-12 relative. Returns 0 if no charge.
    """
    if z_max <= 0.0:
        return 0.0

    def f(r):
        return z_max * z_max * math.exp(-r / screening) * (1.0 / r ** 2 + 1.0 / (screening * r)) - tolerance

    lo, hi = 1e-6, 1e6
    if f(lo) < 0.0:
        return lo
    for _ in range(200):
        mid = math.sqrt(lo * hi)
        if f(mid) > 0.0:
            lo = mid
        else:
            hi = mid
        if hi - lo < 1e-12 * hi:
            break
    return hi


class _Term:
    """One force term. ``channels``: list of (channel name, conservative?).

    ``slow``: with multiple time stepping (``integrator.slow_every > 1``) the term is
    evaluated only on full evaluations and its force held in between (the smooth, costly
    long-range sums); other terms are evaluated every step.
    """

    channels: list = []
    name = ""
    slow = False
    #: the term reads the rod currents: new currents make its held force stale
    uses_currents = False

    def compute(self, ff, out):  # pragma: no cover - interface
        raise NotImplementedError

    def energy(self, ff):
        return None

    def blocked(self, ff):
        """Channels whose last ``compute`` filled only the rows of ``ff.blocks`` (default: none)."""
        return ()

    def split(self, ff, dt):
        """Apply this term's stiff brake exactly over ``dt`` (``integrator.brake = "split"``).

        Modifies ``ff.velocity`` in place and returns {channel: work done}; the work is the
        change of kinetic energy of the tips it touched, exactly.
        """
        return {}


def _kinetic(velocity, tips):
    return 0.5 * float(np.einsum("ij,ij->", velocity[tips], velocity[tips]))


class TipMagnetic(_Term):
    """Term 1. Slow as a whole; with multiple time stepping the force field adds back the fast
    part of the close pairs at every evaluation (:meth:`fast`)."""

    name = "tip_magnetic"
    channels = [("tip_magnetic", True)]
    slow = True

    def __init__(self, p: Parameters, state):
        self.rstar = p.rods.rstar
        self.kappa = p.rods.tip_stiffness
        tm = p.forces.tip_magnetic
        self.tree = tm.method == "tree" or (tm.method == "auto" and state.n_rods >= tm.tree_above)
        self.theta = tm.opening_angle

    def compute(self, ff, out):
        x, y, z = ff.soa()
        lo, hi = ff.blocks.tips
        if self.tree:
            try:
                tree = ktree.build_tip_tree(x, y, z, ff.tip_charge)
            except ValueError:
                if np.isfinite(ff.position).all():
                    raise
                # NaN or inf positions: no tree can place them; the direct sum passes them on
                # to the forces, where the run's health check stops with a diagnosis
            else:
                ktree.evaluate_tip_tree(tree, self.rstar, self.kappa, self.theta, out["tip_magnetic"], lo, hi)
                return
        kt.tip_tip_direct(x, y, z, ff.tip_charge, self.rstar, self.kappa, lo, hi, out["tip_magnetic"])

    def blocked(self, ff):
        return ("tip_magnetic",)

    def fast(self, ff, r_in, r_out, out):
        """The fast part of the force, pairs closer than ``r_out`` switched off smoothly from ``r_in`` on."""
        nl = ff.tip_neighbours()
        kt.tip_tip_fast(ff.position, ff.tip_charge, nl.start, nl.index, self.rstar, self.kappa, r_in, r_out, out)

    def energy(self, ff):
        x, y, z = ff.soa()
        lo, hi = ff.blocks.tips
        e = np.empty(ff.n_tips)
        kt.tip_tip_energy(x, y, z, ff.tip_charge, self.rstar, self.kappa, lo, hi, e)
        ff.blocks.gather_rows([e], rows_per_rod=2)
        return {"tip_magnetic": float(e.sum())}


class TipBrake(_Term):
    name = "tip_brake"
    channels = [("tip_brake", False)]

    def __init__(self, p, state):
        self.rstar = p.rods.rstar
        self.k = p.forces.tip_brake.coefficient
        self.split_mode = p.integrator.brake == "split"

    def compute(self, ff, out):
        if self.split_mode:
            out["tip_brake"].fill(0.0)
            return
        nl = ff.tip_neighbours()
        kp.tip_brake(ff.position, ff.velocity, nl.start, nl.index, self.rstar, self.k, out["tip_brake"])

    def split(self, ff, dt):
        nl = ff.tip_neighbours()
        pairs = kp.close_pairs(ff.position, nl.start, nl.index, self.rstar)
        if not len(pairs):
            return {}
        return {"tip_brake": kp.brake_pairs_exact(ff.velocity, pairs, self.k, dt)}


class AmbientBrake(_Term):
    name = "ambient_brake"
    channels = [("ambient_brake", False)]

    def __init__(self, p, state):
        self.k = p.forces.ambient_brake.coefficient

    def compute(self, ff, out):
        np.multiply(ff.velocity, -self.k, out=out["ambient_brake"])


class UniformField(_Term):
    name = "uniform_field"
    channels = [("uniform_field", True)]

    def __init__(self, p, state):
        self.B = np.array(p.forces.uniform_field.B, dtype=np.float64)

    def compute(self, ff, out):
        np.multiply(ff.tip_charge[:, None], self.B[None, :], out=out["uniform_field"])

    def energy(self, ff):
        return {"uniform_field": -float(ff.tip_charge @ (ff.position @ self.B))}


class PlasmaFilament(_Term):
    name = "plasma_filament"
    channels = [("plasma_filament", False)]

    def __init__(self, p, state):
        pf = p.forces.plasma_filament
        self.args = (float(pf.axis[0]), float(pf.axis[1]), pf.radius, pf.current)

    def compute(self, ff, out):
        kf.plasma_force_on_tips(ff.position, ff.tip_charge, *self.args, out["plasma_filament"])


class Yukawa(_Term):
    name = "yukawa"
    channels = [("yukawa", True)]
    slow = True

    def __init__(self, p, state):
        y = p.forces.yukawa
        self.screening = y.screening_length
        self.core = y.core_radius
        zmax = float(np.abs(state.rod_charge).max(initial=0.0))
        self.cutoff = yukawa_cutoff(zmax, y.screening_length, y.tolerance)

    def compute(self, ff, out):
        if self.cutoff == 0.0:  # no rod is charged: the term is zero
            out["yukawa"].fill(0.0)
            return
        nl = ff.centre_neighbours()
        f = ff.buffer("yukawa_centre", ff.n_rods)
        lo, hi = ff.blocks.rods
        kp.yukawa_centres(ff.centre(), ff.rod_charge, nl.start, nl.index, self.screening, self.core, self.cutoff,
                          lo, hi, f)
        _share_by_mass(f[lo:hi], out["yukawa"][2 * lo:2 * hi])

    def blocked(self, ff):
        return ("yukawa",) if self.cutoff > 0.0 else ()

    def energy(self, ff):
        if self.cutoff == 0.0:
            return {"yukawa": 0.0}
        nl = ff.centre_neighbours()
        lo, hi = ff.blocks.rods
        e = np.empty(ff.n_rods)
        kp.yukawa_energy(ff.centre(), ff.rod_charge, nl.start, nl.index, self.screening, self.core, self.cutoff,
                         lo, hi, e)
        ff.blocks.gather_rows([e], rows_per_rod=1)
        return {"yukawa": float(e.sum())}


class ElectricField(_Term):
    name = "electric_field"
    channels = [("electric_field", True)]

    def __init__(self, p, state):
        self.E = np.array(p.forces.electric_field.E, dtype=np.float64)

    def compute(self, ff, out):
        _share_by_mass(ff.rod_charge[:, None] * self.E[None, :], out["electric_field"])

    def energy(self, ff):
        return {"electric_field": -float(ff.rod_charge @ (ff.centre() @ self.E))}


class Electrodes(_Term):
    name = "electrodes"
    channels = [("electrodes", True), ("electrode_brake", False)]

    def __init__(self, p, state):
        gap = p.forces.electrodes.gap
        self.z = (-0.5 * gap, 0.5 * gap)
        self.rstar = p.rods.rstar
        self.kappa = p.rods.tip_stiffness
        self.k = p.forces.tip_brake.coefficient if p.forces.tip_brake is not None else 0.0
        self.split_mode = p.integrator.brake == "split"

    def compute(self, ff, out):
        k = 0.0 if self.split_mode else self.k
        kf.electrode_walls(ff.position, ff.velocity, self.z[0], self.z[1], self.rstar, self.kappa, k,
                           out["electrodes"], out["electrode_brake"])

    def split(self, ff, dt):
        z = ff.position[:, 2]
        touching = (z - self.z[0] < self.rstar).astype(np.float64) + (self.z[1] - z < self.rstar)
        tips = np.flatnonzero(touching)
        if not len(tips) or self.k == 0.0:
            return {}
        before = _kinetic(ff.velocity, tips)
        ff.velocity[tips] *= np.exp(-self.k * touching[tips] * dt)[:, None]  # dv/dt = -n k v, exactly
        return {"electrode_brake": _kinetic(ff.velocity, tips) - before}

    def energy(self, ff):
        return {"electrodes": kf.electrode_energy(ff.position, self.z[0], self.z[1], self.rstar, self.kappa)}


class ExternalFilament(_Term):
    """Term 11: q_k B of the fixed filament on the z axis (not conservative: the field circles the axis)."""

    name = "external_filament"
    channels = [("external_filament", False)]

    def __init__(self, p, state):
        f = p.forces.external_filament
        self.current, self.w = f.current, 0.5 * f.diameter

    def compute(self, ff, out):
        kx.filament_force_on_tips(ff.position, ff.tip_charge, self.current, self.w, out["external_filament"])


class ExternalDipole(_Term):
    """Term 11: the dipole's end monopoles on tips (tip law and brake) and its screened line charge on rods."""

    name = "external_dipole"
    channels = [("external_monopoles", True), ("external_monopole_brake", False), ("external_line_charge", True)]

    def __init__(self, p, state):
        d = p.forces.external_dipole
        self.source, self.source_charge = external_monopoles(d)
        self.rstar, self.kappa = p.rods.rstar, p.rods.tip_stiffness
        self.k = p.forces.tip_brake.coefficient if p.forces.tip_brake is not None else 0.0
        self.line = (-0.5 * d.length, 0.5 * d.length, d.line_charge, d.screening_length, d.radius)
        self.nodes, self.weights = kc.gauss_legendre_01(d.quadrature_points)
        self.split_mode = p.integrator.brake == "split"

    def compute(self, ff, out):
        k = 0.0 if self.split_mode else self.k
        kx.monopoles_on_tips(ff.position, ff.velocity, ff.tip_charge, self.source, self.source_charge, self.rstar,
                             self.kappa, k, out["external_monopoles"], out["external_monopole_brake"])
        f = ff.buffer("line_centre", ff.n_rods)
        kx.line_yukawa_on_centres(ff.centre(), ff.rod_charge, *self.line, self.nodes, self.weights, f)
        _share_by_mass(f, out["external_line_charge"])

    def split(self, ff, dt):
        d2 = ((ff.position[:, None, :] - self.source[None, :, :]) ** 2).sum(axis=-1)
        touching = (d2 < self.rstar ** 2).sum(axis=1).astype(np.float64)
        tips = np.flatnonzero(touching)
        if not len(tips) or self.k == 0.0:
            return {}
        before = _kinetic(ff.velocity, tips)
        ff.velocity[tips] *= np.exp(-self.k * touching[tips] * dt)[:, None]
        return {"external_monopole_brake": _kinetic(ff.velocity, tips) - before}

    def energy(self, ff):
        return {
            "external_monopoles": kx.monopoles_energy(ff.position, ff.tip_charge, self.source, self.source_charge,
                                                      self.rstar, self.kappa),
            "external_line_charge": kx.line_yukawa_energy(ff.centre(), ff.rod_charge, *self.line, self.nodes,
                                                          self.weights),
        }


def external_monopoles(d):
    """Positions (2, 3) and charges (2,) of the external dipole's end monopoles (moment along +z)."""
    source = np.array([[0.0, 0.0, 0.5 * d.length], [0.0, 0.0, -0.5 * d.length]])
    return source, np.array([d.magnetic_charge, -d.magnetic_charge])


class CurrentField(_Term):
    """Term 9: q_k times the field of all other rods' currents. No kernel call while no rod carries current."""

    name = "current_field"
    channels = [("current_field", False)]
    slow = True
    uses_currents = True

    def __init__(self, p, state):
        self.w = 0.5 * p.rods.diameter

    def compute(self, ff, out):
        f = out["current_field"]
        f.fill(0.0)
        if len(ff.active_rod):
            lo, hi = ff.blocks.tips
            kc.current_force_on_tips(ff.position, ff.tip_charge, ff.active_rod, ff.current, self.w, lo, hi, f)
            ff.calls[self.name] += 1

    def blocked(self, ff):
        return ("current_field",) if len(ff.active_rod) else ()


class CurrentLorentz(_Term):
    """Term 10: J_i s_i x B_tot on current-carrying rods, by Gauss-Legendre quadrature along each rod.

    B_tot = uniform field (if term 4 is on) + plasma filament (if term 5 is on) + the
    external filament and dipole monopoles (if term 11 is on) + the currents of all
    other rods. Only current-carrying rods are visited, and of them only those in the
    field's block of rods (the field at their points still sums over every current).
    """

    name = "current_lorentz"
    channels = [("current_lorentz", False)]
    slow = True
    uses_currents = True

    def __init__(self, p, state):
        self.t, self.wt = kc.gauss_legendre_01(p.forces.current_lorentz.quadrature_points)
        self.w = 0.5 * p.rods.diameter
        f = p.forces
        self.B = np.array(f.uniform_field.B, dtype=np.float64) if f.uniform_field is not None else None
        pf = f.plasma_filament
        self.plasma = (float(pf.axis[0]), float(pf.axis[1]), pf.radius, pf.current) if pf is not None else None
        ef = f.external_filament
        self.filament = (ef.current, 0.5 * ef.diameter) if ef is not None else None
        self.monopoles = external_monopoles(f.external_dipole) if f.external_dipole is not None else None
        self.rstar = p.rods.rstar

    def compute(self, ff, out):
        f = out["current_lorentz"]
        f.fill(0.0)
        active = ff.active_rod
        if not len(active):
            return
        ff.calls[self.name] += 1
        # active_rod is sorted (set_currents), so the rods of this block are one slice of it
        mine = active[np.searchsorted(active, ff.blocks.rods[0]):np.searchsorted(active, ff.blocks.rods[1])]
        if not len(mine):
            return
        ng = len(self.t)
        pts = ff.buffer("gl_points", len(mine) * ng)
        kc.quadrature_points(ff.position, mine, self.t, pts)
        field = ff.buffer("gl_field", len(mine) * ng)
        kc.rod_current_field(pts, np.repeat(mine, ng), ff.position, active, ff.current, self.w, field)
        if self.B is not None:
            field += self.B
        extra = ff.buffer("gl_extra", len(pts))
        if self.plasma is not None:
            kf.plasma_field(pts, *self.plasma, extra)
            field += extra
        if self.filament is not None:
            kx.filament_field(pts, *self.filament, extra)
            field += extra
        if self.monopoles is not None:
            kx.monopole_field(pts, *self.monopoles, self.rstar, extra)
            field += extra
        kc.lorentz_force_on_rods(ff.position, mine, ff.current, field, self.t, self.wt, f)

    def blocked(self, ff):
        return ("current_lorentz",) if len(ff.active_rod) else ()


def _share_by_mass(centre_force, tip_out):
    """A force on a rod centre goes half to each tip (equal masses; paper Eqs. 5-6)."""
    tip_out[0::2] = 0.5 * centre_force
    tip_out[1::2] = 0.5 * centre_force


TERM_CLASSES = {cls.name: cls for cls in (TipMagnetic, TipBrake, AmbientBrake, UniformField, PlasmaFilament,
                                         Yukawa, ElectricField, Electrodes, ExternalFilament, ExternalDipole,
                                         CurrentField, CurrentLorentz)}
#: terms that count their own kernel calls (only when a rod carries current)
_SELF_COUNTING = ("current_field", "current_lorentz")


class ForceField:
    """The force terms of one scene, with their buffers and neighbour lists.

    Parameters
    ----------
    params : Parameters
    state : State
        Supplies the per-tip and per-rod constants (charges) and the sizes.
    timing : bool
        Accumulate wall time per term in ``self.seconds`` (for benchmarks).
    blocks : RowBlocks, optional
        The rods whose rows this process computes in the expensive terms (default: all of
        them, a serial run).

    Attributes
    ----------
    terms : list of the active term objects, docs/model.md order ('Force terms')
    channels : list of (name, conservative)
    calls : Counter of kernel evaluations per term (tests count these)
    """

    def __init__(self, params: Parameters, state, timing: bool = False, blocks: RowBlocks | None = None):
        self.params = params
        self.blocks = RowBlocks(state.n_rods) if blocks is None else blocks
        if self.blocks.n_rods != state.n_rods:
            raise ValueError(f"the row blocks cover {self.blocks.n_rods} rods, the state has {state.n_rods}")
        self.tip_charge = state.tip_charge
        self.rod_charge = state.rod_charge
        self.n_tips = state.n_tips
        self.n_rods = state.n_rods
        self.terms = [TERM_CLASSES[name](params, state) for name in params.forces.active()]
        self.channels = [c for t in self.terms for c in t.channels]
        self.nonconservative = [name for name, cons in self.channels if not cons]
        self.conservative = [name for name, cons in self.channels if cons]
        self.out = {name: np.zeros((self.n_tips, 3)) for name, _ in self.channels}
        self.total = np.zeros((self.n_tips, 3))
        self.calls = Counter()
        self.timing = timing
        self.seconds = Counter()
        self._buffers = {}
        skin = params.neighbours.skin
        self._tip_nl = None
        self._centre_nl = None
        self._tip_range = params.rods.rstar
        for t in self.terms:
            if isinstance(t, Yukawa) and t.cutoff > 0.0:
                self._centre_nl = NeighbourList(t.cutoff, skin)
        self._skin = skin
        self.position = None
        self.velocity = None
        self.current = np.zeros(self.n_rods)
        self.active_rod = np.zeros(0, dtype=np.int64)
        # multiple time stepping (integrator.slow_every > 1): the slow terms' channels keep their
        # last evaluation; the tip term's far part is kept apart from its fast close pairs
        ip = params.integrator
        self.slow_every = ip.slow_every
        self.multiple_time_stepping = ip.slow_every > 1
        self._tip_term = next((t for t in self.terms if isinstance(t, TipMagnetic)), None)
        if self.multiple_time_stepping and self._tip_term is not None:
            rstar = params.rods.rstar
            self.fast_range = ((ip.fast_range - 1.0) * rstar, ip.fast_range * rstar)
            self.extend_tip_range(self.fast_range[1])
            self.tip_far = np.zeros((self.n_tips, 3))
            self._tip_fast = np.zeros((self.n_tips, 3))
        #: slow term name -> the held arrays it refreshes (``held_forces`` keys)
        self._slow_keys = {t.name: (["tip_far"] if isinstance(t, TipMagnetic) else [c for c, _ in t.channels])
                           for t in self.terms if t.slow}
        #: slow terms whose inputs changed (new currents): computed at the next evaluation, full or not
        self.stale = set(self._slow_keys)
        self.extrapolate = self.multiple_time_stepping and ip.slow_extrapolation
        if self.extrapolate:
            self._base = {k: np.zeros_like(v) for k, v in self.held_forces().items()}
            self._rate = {k: np.zeros_like(v) for k, v in self.held_forces().items()}
            self._base_step = {k: None for k in self._base}

    def set_currents(self, current):
        """Rod currents from the last circuit solve, (n_rods,) float64; used from the next evaluation on.

        Rods whose current is exactly zero are left out of the current kernels.
        """
        current = np.ascontiguousarray(current, dtype=np.float64)
        if current.shape != (self.n_rods,):
            raise ValueError(f"currents must have shape ({self.n_rods},), got {current.shape}")
        # [perf] the same currents again (an event in a structure that carries none): the held current
        # forces stay valid, so nothing turns stale (late in Fig. 2 half the solves; docs/performance.md)
        if np.array_equal(current, self.current):
            return
        self.current = current
        self.active_rod = np.flatnonzero(current != 0.0).astype(np.int64)
        if self.multiple_time_stepping:
            self.stale.update(t.name for t in self.terms if t.slow and t.uses_currents)

    # -- lazily computed views of the current (position, velocity) ---------------------------------
    def _bind(self, position, velocity):
        self.position = position
        self.velocity = velocity
        self._soa = None
        self._centre = None

    def soa(self):
        if self._soa is None:
            self._soa = tuple(np.ascontiguousarray(self.position[:, d]) for d in range(3))
        return self._soa

    def centre(self):
        if self._centre is None:
            self._centre = 0.5 * (self.position[0::2] + self.position[1::2])
        return self._centre

    def buffer(self, name, rows):
        buf = self._buffers.get(name)
        if buf is None or buf.shape[0] != rows:
            buf = self._buffers[name] = np.zeros((rows, 3))
        return buf

    def tip_neighbours(self, position=None) -> NeighbourList:
        """Tip pairs of different rods closer than the tip range (plus skin), up to date for ``position``.

        The range is r*, or the contact release radius once :meth:`extend_tip_range`
        was called, so that the brake and the contact search share one list.
        """
        if self._tip_nl is None:
            self._tip_nl = NeighbourList(self._tip_range, self._skin, exclude_same_rod=True)
        self._tip_nl.update(self.position if position is None else position)
        return self._tip_nl

    def extend_tip_range(self, radius: float) -> None:
        """Make the tip neighbour list cover ``radius`` (the contact release radius)."""
        if radius > self._tip_range:
            self._tip_range = float(radius)
            self._tip_nl = None

    def centre_neighbours(self) -> NeighbourList:
        self._centre_nl.update(self.centre())
        return self._centre_nl

    # -- evaluation -------------------------------------------------------------------------------
    def evaluate(self, position, velocity, power=None, full=True, step=None):
        """Total force on every tip at (position, velocity).

        Parameters
        ----------
        position, velocity : (n_tips, 3) float64
        power : (len(nonconservative),) float64, optional
            Filled with ``sum_k F_k . v_k`` of each non-conservative channel.
        full : bool
            With multiple time stepping: False evaluates only the fast terms, the fast part
            of the tip-tip force and the slow terms whose inputs changed (new currents), and
            adds the other slow forces as extrapolated (or held) from their last evaluations.
            Ignored (always full) without it.
        step : int, optional
            The step this evaluation starts (None inside the RK4 stages): the clock of the
            extrapolation.

        Returns
        -------
        (n_tips, 3) float64
            The summed force (a buffer owned by the field; copy it to keep it).
        """
        self._bind(position, velocity)
        mts = self.multiple_time_stepping
        full = full or not mts
        blocked = []
        refreshed = []
        for t in self.terms:
            if t.slow:
                if not (full or t.name in self.stale):
                    continue
                refreshed.append(t.name)
            t0 = time.perf_counter() if self.timing else 0.0
            t.compute(self, self.out)
            if t.name not in _SELF_COUNTING:
                self.calls[t.name] += 1
            if self.timing:
                self.seconds[t.name] += time.perf_counter() - t0
            blocked.extend(t.blocked(self))
        if not self.blocks.serial:
            t0 = time.perf_counter() if self.timing else 0.0
            self.blocks.gather_rows([self.out[name] for name in blocked], rows_per_rod=2)
            if self.timing:
                self.seconds["gather"] += time.perf_counter() - t0
        if mts:
            self.stale.clear()
            fast = None
            tip_fresh = "tip_magnetic" in refreshed
            if self._tip_term is not None:
                t0 = time.perf_counter() if self.timing else 0.0
                fast = self._tip_fast
                self._tip_term.fast(self, *self.fast_range, fast)
                if tip_fresh:
                    np.subtract(self.out["tip_magnetic"], fast, out=self.tip_far)
                if self.timing:
                    self.seconds["tip_magnetic_fast"] += time.perf_counter() - t0
            if self.extrapolate:
                self._extrapolate([k for name in refreshed for k in self._slow_keys[name]], full, step)
            if fast is not None and not tip_fresh:
                np.add(self.tip_far, fast, out=self.out["tip_magnetic"])
        total = self.total
        total.fill(0.0)
        for name, _ in self.channels:
            total += self.out[name]
        if power is not None:
            for j, name in enumerate(self.nonconservative):
                power[j] = np.einsum("ij,ij->", self.out[name], velocity)
        return total

    def _extrapolate(self, refreshed, full, step):
        """Linear extrapolation in time of each held slow force from its last two evaluations.

        A force just ``refreshed`` becomes the new base; its rate is the difference from the
        previous base over the steps between them when both were full evaluations at step
        starts at most 2 K apart, else zero (after an RK4 start, or when the currents changed:
        a jump, not a trend). The others are extrapolated to ``step``.
        """
        for key, arr in self.held_forces().items():
            base, rate, prev = self._base[key], self._rate[key], self._base_step[key]
            if key in refreshed:
                gap = None if (prev is None or step is None or not full) else step - prev
                if gap is not None and 0 < gap <= 2 * self.slow_every:
                    np.subtract(arr, base, out=rate)
                    rate /= gap
                else:
                    rate.fill(0.0)
                base[:] = arr
                self._base_step[key] = step if full else None
            elif prev is not None and step is not None:
                np.multiply(rate, step - prev, out=arr)
                arr += base

    def held_forces(self) -> dict:
        """The slow forces held between full evaluations (multiple time stepping), by name
        (the slow channels and ``tip_far``, the tip-tip force less its fast part); views, not copies."""
        if not self.multiple_time_stepping:
            return {}
        return {key: (self.tip_far if key == "tip_far" else self.out[key])
                for keys in self._slow_keys.values() for key in keys}

    def mts_state(self) -> dict:
        """What the next evaluations depend on besides the state (multiple time stepping), as copies:
        held forces, the stale terms and, with extrapolation, bases, rates and their steps."""
        if not self.multiple_time_stepping:
            return {}
        snap = {f"mts_held_{k}": v.copy() for k, v in self.held_forces().items()}
        snap["mts_stale"] = np.array([name in self.stale for name in self._slow_keys], dtype=bool)
        if self.extrapolate:
            snap.update({f"mts_base_{k}": v.copy() for k, v in self._base.items()})
            snap.update({f"mts_rate_{k}": v.copy() for k, v in self._rate.items()})
            snap["mts_base_step"] = np.array([-1 if b is None else b for b in self._base_step.values()],
                                             dtype=np.int64)
        return snap

    def restore_mts_state(self, snap: dict) -> bool:
        """Put back what :meth:`mts_state` returned; False (every slow term then computed at the next
        evaluation) when ``snap`` was taken with other settings, e.g. without multiple time stepping."""
        mine = self.mts_state()
        if not mine or set(mine) - set(snap) or np.shape(snap["mts_stale"]) != mine["mts_stale"].shape:
            return False
        for k, v in self.held_forces().items():
            v[:] = snap[f"mts_held_{k}"]
        self.stale = {name for name, flag in zip(self._slow_keys, np.asarray(snap["mts_stale"])) if flag}
        if self.extrapolate:
            for k in self._base:
                self._base[k][:] = snap[f"mts_base_{k}"]
                self._rate[k][:] = snap[f"mts_rate_{k}"]
            steps = np.asarray(snap["mts_base_step"])
            self._base_step = {k: (None if b < 0 else int(b)) for k, b in zip(self._base, steps)}
        return True

    def split_brakes(self, position, velocity, dt, work):
        """``integrator.brake = "split"``: apply every stiff brake exactly over ``dt`` (velocity in place).

        ``work`` (len(nonconservative),) is incremented by each brake's work.
        """
        self._bind(position, velocity)
        for t in self.terms:
            for channel, w in t.split(self, dt).items():
                work[self.nonconservative.index(channel)] += w

    def potential_energy(self, position) -> dict:
        """Potential energy of each conservative channel at ``position``."""
        self._bind(position, np.zeros_like(position) if self.velocity is None else self.velocity)
        energy = {}
        for t in self.terms:
            e = t.energy(self)
            if e:
                energy.update(e)
        return energy

    def dominant_channel(self, rows) -> str:
        """Name of the channel with the largest force on the given tips (for failure diagnoses);
        a non-finite force (NaN or inf) counts as the largest."""
        return self.dominant_force(rows)[0]

    def dominant_force(self, rows) -> tuple[str, float]:
        """(channel, largest force component) of the channel with the largest force on the given
        tips; NaN counts as inf. ("none", 0.0) without channels."""
        best, name = -1.0, "none"
        for ch, _ in self.channels:
            m = float(np.nan_to_num(np.abs(self.out[ch][rows]), nan=np.inf).max(initial=0.0))
            if m > best:
                best, name = m, ch
        return name, max(best, 0.0)

    def describe(self) -> dict:
        """Resolved settings derived from the parameters (e.g. the Yukawa cut-off radius)."""
        d = {"terms": [t.name for t in self.terms]}
        for t in self.terms:
            if isinstance(t, TipMagnetic):
                d["tip_magnetic_sum"] = f"tree (opening angle {t.theta:g})" if t.tree else "direct"
            if isinstance(t, Yukawa):
                d["yukawa_cutoff"] = t.cutoff
        return d
