"""Runs of fast steps in one compiled call (docs/model.md 'Order of one step', 'Multiple time stepping
(`integrator.slow_every`)'; docs/performance.md 'Fast steps in one compiled call').

Under multiple time stepping most steps evaluate only the fast terms and extrapolate the held slow
forces. :func:`fast_steps` runs such steps one after another, each in the order of the Python step
(``model/integrator.py::AdamsBashforth4.step`` with ``model/terms/forcefield.py::ForceField.evaluate``,
then the health check and the contact test of ``model/simulation.py::Simulation.step``), by calling
the kernels the Python step calls, with the same arguments: the same numbers bit for bit. It
returns at the first step that needs Python:

- ``NEEDS_STEP``: before a step that must run in Python (a slow evaluation, a slow term made stale
  by new currents, the RK4 start, or a tip neighbour list due for a rebuild, found before the step
  or, for the split tip brake, after its update: the step is then undone, positions and velocities
  put back);
- ``NEEDS_CONTACTS``: after a step whose contact test needs Python (the quiet-step test
  ``pairs.py::contacts_unchanged`` is not sure, a filament contact moved along z, or the list is
  due for a rebuild at the new positions);
- ``NEEDS_HEALTH``: after a step that fails the run's health check (Python then raises the diagnosis);
- ``DONE``: after ``n_max`` steps.

What the Python step accumulates in other objects is logged per step for the caller
(``model/compiled.py``): the bond error before the constraint (the run file's per-step rows), the
power of each non-conservative channel and the split brakes' work (the integrator's work, summed
there with numpy's matrix product, as the Python step sums it).

The O(n) kernels are called in their serial builds (``njit_rows``'s ``serial``): the caller uses
this path below ``_jit.PARALLEL_ROWS`` tips only, where the Python step calls those builds too.
"""

import math

import numpy as np

from ._jit import njit
from .brakes import brake_close_pairs_exact, tip_brake
from .cells import max_displacement2
from .contacts import contacts_unchanged
from .external import filament_force_on_tips, line_yukawa_on_centres, monopoles_on_tips
from .fields import electrode_brake_exact, electrode_walls, plasma_force_on_tips
from .integrate import ab4_step, channel_sum_power, dot_as_numpy
from .rigid import bond_acceleration, constrain_bonds_checked
from .tips import tip_tip_fast

DONE, NEEDS_STEP, NEEDS_CONTACTS, NEEDS_HEALTH = 0, 1, 2, 3

#: the channels a run of fast steps writes, by their place in the ``channel`` argument of :func:`fast_steps`
CHANNELS = (
    "tip_magnetic",
    "tip_brake",
    "ambient_brake",
    "plasma_filament",
    "electrodes",
    "electrode_brake",
    "external_filament",
    "external_monopoles",
    "external_monopole_brake",
    "external_line_charge",
)
#: the split brakes whose work is logged, in the order of the terms (the column of ``brake_work``)
SPLIT_BRAKES = ("tip_brake", "electrode_brake", "external_monopole_brake")

_ab4_step = ab4_step.serial
_channel_sum_power = channel_sum_power.serial
_bond_acceleration = bond_acceleration.serial
_constrain_bonds_checked = constrain_bonds_checked.serial
_electrode_walls = electrode_walls.serial
_plasma_force_on_tips = plasma_force_on_tips.serial
_filament_force_on_tips = filament_force_on_tips.serial
_monopoles_on_tips = monopoles_on_tips.serial
_line_yukawa_on_centres = line_yukawa_on_centres.serial
_tip_tip_fast = tip_tip_fast.serial


@njit
def _all_plus_zero(a):
    """Whether every element of the C-contiguous array ``a`` is +0.0 (the bits of +0.0 are all 0)."""
    bits = a.reshape(-1).view(np.int64)
    for k in range(bits.shape[0]):
        if bits[k] != 0:
            return False
    return True


@njit
def _list_due(position, reference, half_skin2):
    """``NeighbourList.update``'s test: True when a point moved by ``skin / 2`` or more since the build."""
    return not max_displacement2(position, reference) < half_skin2


@njit
def _sources_within(position, k, source, r2):
    """How many of ``source`` lie closer than sqrt(r2) to tip ``k``."""
    n = 0
    for s in range(source.shape[0]):
        dx = position[k, 0] - source[s, 0]
        dy = position[k, 1] - source[s, 1]
        dz = position[k, 2] - source[s, 2]
        if (dx * dx + dy * dy) + dz * dz < r2:
            n += 1
    return n


@njit
def _monopole_brake_exact(position, velocity, source, rstar, decay, before, after):
    """The split brake of the external dipole's monopoles (``model/terms/external.py``,
    ``ExternalDipoleForce.split``) over one step, bit for bit: a tip within r* of n monopoles has
    its velocity multiplied by ``decay[n]`` (computed by the caller with numpy's ``exp``); the work is
    the change of the touched tips' kinetic energy, summed as numpy's ``einsum`` sums it. Returns
    (work, touched tips)."""
    r2 = rstar * rstar
    m = 0
    for k in range(position.shape[0]):
        n = _sources_within(position, k, source, r2)
        if n:
            for d in range(3):
                before[m, d] = velocity[k, d]
            m += 1
    if not m:
        return 0.0, 0
    flat_before = before.reshape(-1)
    kinetic_before = 0.5 * dot_as_numpy(flat_before, flat_before, 3 * m)
    m = 0
    for k in range(position.shape[0]):
        n = _sources_within(position, k, source, r2)
        if n:
            for d in range(3):
                velocity[k, d] = velocity[k, d] * decay[n]
                after[m, d] = velocity[k, d]
            m += 1
    flat_after = after.reshape(-1)
    kinetic_after = 0.5 * dot_as_numpy(flat_after, flat_after, 3 * m)
    return kinetic_after - kinetic_before, m


@njit
def fast_steps(
    x,
    v,
    hist_v,
    hist_a,
    hist_p,
    head,
    slot_table,
    step,
    n_max,
    slow_every,
    dt,
    length,
    exact_bond,
    project,
    correct_velocity,
    block,
    total,
    powered,
    channel,
    tip_charge,
    rod_charge,
    scalars,
    plasma,
    decay_walls,
    decay_poles,
    source,
    source_charge,
    line,
    nodes,
    weights,
    held,
    tip_far,
    tip_fast,
    rate,
    base,
    base_step,
    extrapolate,
    lists,
    start,
    index,
    reference,
    pairs,
    on_cathode,
    on_anode,
    on_filament,
    filament_tip,
    filament_z,
    centre,
    centre_force,
    before,
    after,
    save_x,
    save_v,
    bond_before,
    power_log,
    brake_work,
    brake_hit,
    limits,
):
    """Up to ``n_max`` fast steps from ``step``, in place; returns ``(steps, reason, head, max_bond_error,
    bond_error_after, speed_max)`` with ``reason`` one of the module's codes.

    Parameters
    ----------
    x, v : (n_tips, 3) float64, positions and velocities, advanced in place
    hist_v, hist_a : (4, n_tips, 3) float64; hist_p : (4, n_power) float64
        The integrator's ring buffers; ``head`` the slot of the last step's derivatives;
        ``slot_table`` (4, 4) int64, row h: the slots of f_n, ..., f_{n-3} when f_n is in slot h.
    step, n_max, slow_every : int
    dt : float
    length : (n_rods,) float64 or empty; exact_bond, project, correct_velocity : bool
        As ``AdamsBashforth4`` takes them.
    block : (n_channels, n_tips, 3) float64
        The force field's channel buffers; ``total`` (n_tips, 3) their sum; ``powered`` the
        non-conservative channels' rows.
    channel : (len(CHANNELS),) int64
        Each channel's row in ``block``, -1 for a channel that is off (or, for the line charge, slow:
        then it is one of the held forces).
    tip_charge : (n_tips,) float64; rod_charge : (n_rods,) float64
    scalars : (17,) float64
        ambient brake coefficient; tip law r*, kappa; tip brake coefficient (explicit; NaN: split);
        split tip brake coefficient (0: none); electrode planes z_c, z_a, explicit electrode
        brake; split electrode brake (0: none); filament current and radius; monopole brake
        (explicit); split monopole brake (0: none); fast range r_in, r_out; neighbour list
        (skin / 2)^2; contact release radius.
    plasma : (4,) float64 or empty
        Axis x, y, radius and current of the plasma filament.
    decay_walls, decay_poles : (3,) float64
        The split brakes' decay per planes or poles touched.
    source, source_charge : (2, 3), (2,) float64
        The external dipole's monopoles (empty without).
    line : (5,) float64; nodes, weights : float64
        The line charge's ends, density, screening length and radius; its quadrature (empty without).
    held : (n_held,) int64
        Each held slow force's row in ``block``, -1 for ``tip_far`` (the tip-tip force less its fast part).
    tip_far, tip_fast : (n_tips, 3) float64 (empty rows without the tip-tip term)
    rate, base : (n_held, n_tips, 3) float64; base_step : (n_held,) int64, -1: held, not extrapolated
    extrapolate : bool
    lists : (3,) bool
        Where the Python step asks the tip list for an update: in the evaluation (tip-tip fast part,
        explicit tip brake), in the split tip brake, in the contact test.
    start, index, reference : the tip list and the positions of its build
    pairs, on_cathode, on_anode, on_filament : the contacts as the contact test reads them
        (``ContactSet.search_arrays``); ``limits[0]`` 1.0 when a network tests contacts
    filament_tip, filament_z : the case (ii) filament contacts and their heights at the last solve
    centre, centre_force : (n_rods, 3) float64 scratch (the line charge's rod centres and forces)
    before, after, save_x, save_v : (n_tips, 3) float64 scratch
    bond_before : (n_max,) float64; power_log : (n_max, n_power); brake_work : (n_max, 3) float64;
    brake_hit : (n_max, 3) bool
        Per step: the bond error before the constraint, the channels' power, the split brakes' work
        and whether each brake acted (the logs the caller replays).
    limits : (8,) float64
        network on (1.0) or off, electrode planes for the contact test (NaN: none), filament surface
        radius (NaN: none), height tolerance, health limits BOND_BREAK and MAX_STEP_DISPLACEMENT,
        the largest bond error so far.
    """
    amb_k, rstar, kappa, tb_k, tb_split = scalars[0], scalars[1], scalars[2], scalars[3], scalars[4]
    z_c, z_a, wall_k, wall_split = scalars[5], scalars[6], scalars[7], scalars[8]
    fil_current, fil_w, pole_k, pole_split = scalars[9], scalars[10], scalars[11], scalars[12]
    r_in, r_out, half_skin2, release = scalars[13], scalars[14], scalars[15], scalars[16]
    network = limits[0] == 1.0
    c_zc, c_za, c_surface, height_tol = limits[1], limits[2], limits[3], limits[4]
    bond_break, max_move, max_bond = limits[5], limits[6], limits[7]
    c_tip, c_tb, c_amb, c_pl, c_wall, c_wb, c_fil, c_pole, c_pb, c_line = (
        channel[0],
        channel[1],
        channel[2],
        channel[3],
        channel[4],
        channel[5],
        channel[6],
        channel[7],
        channel[8],
        channel[9],
    )
    n = x.shape[0]
    err_after = 0.0
    speed = 0.0
    done = 0
    checked = False  # the tip list's update test already made at the current positions
    # held forces whose rate and base are all +0 (the current terms while no rod carries current):
    # rate * s + base is then +0 on every step, written on the first step of the call only
    zero = np.zeros(held.shape[0], dtype=np.bool_)
    if extrapolate:
        for j in range(held.shape[0]):
            zero[j] = base_step[j] >= 0 and _all_plus_zero(rate[j]) and _all_plus_zero(base[j])
    while done < n_max:
        # the Python step runs the slow evaluations, the RK4 start and the list builds
        if step % slow_every == 0:
            return done, NEEDS_STEP, head, max_bond, err_after, speed
        # (not again when the contact test of the step before found the list fresh at these positions)
        if lists[0] and not checked and _list_due(x, reference, half_skin2):
            return done, NEEDS_STEP, head, max_bond, err_after, speed
        checked = False
        if lists[1]:
            for k in range(n):
                for d in range(3):
                    save_x[k, d] = x[k, d]
                    save_v[k, d] = v[k, d]
        h = (head + 1) % 4
        for k in range(n):
            for d in range(3):
                hist_v[h, k, d] = v[k, d]
        # -- the fast terms (ForceField.evaluate, full=False), each into its channel; the constant
        # channels (uniform field, electric field, the split tip brake's zeros) keep their values
        if c_tb >= 0 and tb_k == tb_k:
            tip_brake(x, v, start, index, rstar, tb_k, block[c_tb])
        if c_amb >= 0:
            out = block[c_amb]
            for k in range(n):
                for d in range(3):
                    out[k, d] = v[k, d] * -amb_k
        if c_pl >= 0:
            _plasma_force_on_tips(x, tip_charge, plasma[0], plasma[1], plasma[2], plasma[3], block[c_pl])
        if c_wall >= 0:
            _electrode_walls(x, v, z_c, z_a, rstar, kappa, wall_k, block[c_wall], block[c_wb])
        if c_fil >= 0:
            _filament_force_on_tips(x, tip_charge, fil_current, fil_w, block[c_fil])
        if c_pole >= 0:
            _monopoles_on_tips(
                x, v, tip_charge, source, source_charge, rstar, kappa, pole_k, block[c_pole], block[c_pb]
            )
        if c_line >= 0:  # -1 also when the line charge is slow (held with the slow forces)
            for i in range(n // 2):
                for d in range(3):
                    centre[i, d] = 0.5 * (x[2 * i, d] + x[2 * i + 1, d])
            _line_yukawa_on_centres(
                centre, rod_charge, line[0], line[1], line[2], line[3], line[4], nodes, weights, centre_force
            )
            out = block[c_line]
            for i in range(n // 2):
                for d in range(3):
                    out[2 * i, d] = 0.5 * centre_force[i, d]
                    out[2 * i + 1, d] = 0.5 * centre_force[i, d]
        # -- MultipleTimeStepping.complete: the tip-tip fast part, the held forces extrapolated
        if c_tip >= 0:
            _tip_tip_fast(x, tip_charge, start, index, rstar, kappa, r_in, r_out, tip_fast)
        if extrapolate:
            for j in range(held.shape[0]):
                if base_step[j] < 0 or (zero[j] and done > 0):
                    continue
                s = float(step - base_step[j])
                o = tip_far if held[j] < 0 else block[held[j]]
                r, b = rate[j], base[j]
                for k in range(n):
                    for d in range(3):
                        o[k, d] = r[k, d] * s + b[k, d]
        if c_tip >= 0:
            out = block[c_tip]
            for k in range(n):
                for d in range(3):
                    out[k, d] = tip_far[k, d] + tip_fast[k, d]
        _channel_sum_power(total, block, v, powered, hist_p[h])
        # -- AdamsBashforth4.step
        _bond_acceleration(total, v, x, exact_bond, hist_a[h])
        err_before = _ab4_step(x, v, hist_v, hist_a, slot_table[h], dt, length)
        for c in range(3):
            brake_hit[done, c] = False
            brake_work[done, c] = 0.0
        if tb_split != 0.0:
            if _list_due(x, reference, half_skin2):
                # the split brake would rebuild the list here: undo the step, Python takes it
                for k in range(n):
                    for d in range(3):
                        x[k, d] = save_x[k, d]
                        v[k, d] = save_v[k, d]
                return done, NEEDS_STEP, head, max_bond, err_after, speed
            w, m = brake_close_pairs_exact(x, v, start, index, rstar, tb_split, dt)
            if m:
                brake_work[done, 0] = w
                brake_hit[done, 0] = True
        if wall_split != 0.0:
            w, m = electrode_brake_exact(x, v, z_c, z_a, rstar, decay_walls, before, after)
            if m:
                brake_work[done, 1] = w
                brake_hit[done, 1] = True
        if pole_split != 0.0:
            w, m = _monopole_brake_exact(x, v, source, rstar, decay_poles, before, after)
            if m:
                brake_work[done, 2] = w
                brake_hit[done, 2] = True
        err_after, speed = _constrain_bonds_checked(x, v, project, correct_velocity, length)
        for c in range(power_log.shape[1]):
            power_log[done, c] = hist_p[h, c]
        bond_before[done] = err_before
        head = h
        step += 1
        done += 1
        # -- HealthChecks.after_step
        if err_after > max_bond:
            max_bond = err_after
        if not (
            math.isfinite(err_before) and err_before < bond_break and speed * dt < max_move and math.isfinite(speed)
        ):
            return done, NEEDS_HEALTH, head, max_bond, err_after, speed
        # -- the network's contact test (Network.update on a step without news)
        if network:
            if lists[2]:
                if _list_due(x, reference, half_skin2):
                    return done, NEEDS_CONTACTS, head, max_bond, err_after, speed
                checked = True
            if not contacts_unchanged(
                x, start, index, pairs, rstar, release, c_zc, c_za, on_cathode, on_anode, c_surface, on_filament
            ):
                return done, NEEDS_CONTACTS, head, max_bond, err_after, speed
            for j in range(filament_tip.shape[0]):
                if abs(x[filament_tip[j], 2] - filament_z[j]) > height_tol:
                    return done, NEEDS_CONTACTS, head, max_bond, err_after, speed
    return done, DONE, head, max_bond, err_after, speed


@njit
def add_work(work, ab4_work, brake_work, brake_hit, split_channel):
    """The integrator's work of a run of steps, added in the Python step's order: for each step its AB4
    sum of the channels' powers (``ab4_work[i]``, as numpy's product gives it), then the work of each
    split brake that acted (``brake_work[i, j]`` into channel ``split_channel[j]``, -1: none).

    Parameters
    ----------
    work : (n_power,) float64, added to in place
    ab4_work : (n_steps, n_power) float64
    brake_work : (n_steps, 3) float64; brake_hit : (n_steps, 3) bool; split_channel : (3,) int64
    """
    for i in range(ab4_work.shape[0]):
        for c in range(work.shape[0]):
            work[c] += ab4_work[i, c]
        for j in range(split_channel.shape[0]):
            if split_channel[j] >= 0 and brake_hit[i, j]:
                work[split_channel[j]] += brake_work[i, j]
