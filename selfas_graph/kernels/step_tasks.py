"""The tasks of a compiled fast step (``steps.py``): what each phase of a step does to one block of rods
or one group of channels, and the split brakes (docs/performance.md 'Fast steps on both cores').

:func:`run_tasks` claims the tasks of a phase (``team.py``) and runs them: the forces of a block
(:func:`forces`), its AB4 update and the channels' powers, its constraint, the pair search of the split
tip brake, the contact test; the split brakes (:func:`split_brakes`) over all tips as one task. A block
writes its own rows only (reading every position), so that its tasks may run in any order on any
thread; each calls the kernels the Python step calls, on the block's rows, with the same operations
per element: the same numbers as over all rows.
"""

from . import team
from ._jit import inline, njit
from .brakes import brake_found_pairs, close_pairs_rows, tip_brake_rows
from .cells import max_displacement2
from .contacts import contacts_part
from .external import filament_force_on_tips, line_yukawa_on_centres, monopoles_on_tips
from .fields import electrode_brake_exact, electrode_walls, plasma_force_on_tips
from .integrate import ab4_rods, dot_as_numpy, power_group, sum_rows_range
from .rigid import bond_acceleration, constrain_bonds_checked
from .step_args import (
    LIM_ANODE_Z,
    LIM_CATHODE_Z,
    LIM_FILAMENT_R,
    LIM_NETWORK,
    SC_AMBIENT_K,
    SC_ANODE_Z,
    SC_CATHODE_Z,
    SC_FAST_INNER,
    SC_FAST_OUTER,
    SC_FILAMENT_CURRENT,
    SC_FILAMENT_W,
    SC_KAPPA,
    SC_POLE_K,
    SC_POLE_SPLIT,
    SC_RELEASE,
    SC_RSTAR,
    SC_TIP_BRAKE_K,
    SC_TIP_BRAKE_SPLIT,
    SC_WALL_K,
    SC_WALL_SPLIT,
)
from .tips import tip_tip_fast_rows

_bond_acceleration = bond_acceleration.serial
_constrain_bonds_checked = constrain_bonds_checked.serial
_electrode_walls = electrode_walls.serial
_plasma_force_on_tips = plasma_force_on_tips.serial
_filament_force_on_tips = filament_force_on_tips.serial
_monopoles_on_tips = monopoles_on_tips.serial
_line_yukawa_on_centres = line_yukawa_on_centres.serial


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


#: the kinds of phase of a step (``team.py``): the tip list's update test before the step, the forces, the
#: AB4 update with the channels' powers, the step undone, the close pairs of the split tip brake, the split
#: brakes, the constraint, the contact test
DUE, FORCES, UPDATE, UNDO, PAIRS, BRAKES, CONSTRAIN, CONTACTS = 1, 2, 3, 4, 5, 6, 7, 8
#: phases a step opens at most
PHASES_PER_STEP = 7
#: the columns of ``partial``: the tip list's displacement before the step, the bond error after the
#: update, the displacement after it, the bond error and the largest velocity after the constraint, the
#: displacement after it
P_DUE, P_BOND, P_DUE_SPLIT, P_BOND_AFTER, P_SPEED, P_DUE_AFTER = 0, 1, 2, 3, 4, 5


@inline
def _copy_rows(dst, src, t0, t1):
    """Rows ``t0`` to ``t1`` of ``src`` into ``dst`` (both (n, 3), C-contiguous), as one flat loop (numpy's
    slice assignment in numba: 15 against 6 us for 12 000 rows, Zen 5)."""
    d = dst.reshape(-1)[3 * t0 : 3 * t1]
    s = src.reshape(-1)[3 * t0 : 3 * t1]
    for i in range(d.shape[0]):
        d[i] = s[i]


@njit
def block_rows(c, chunks, n):
    """Rods and tips of block ``c``: ``(first rod, rod past the last, first tip, tip past the last)``;
    the last block also takes a tip without a partner."""
    n_rods = n // 2
    r0 = c * n_rods // chunks
    r1 = (c + 1) * n_rods // chunks
    return r0, r1, 2 * r0, n if c == chunks - 1 else 2 * r1


@njit
def run_tasks(p, args, s):
    """Claim and run tasks of phase ``p`` until none is left (``args``: the call's
    :class:`~.step_args.FastStepArgs`, ``s`` its :class:`~.step_args.Scratch`)."""
    ctl, partial, counts, chunks = s.ctl, s.partial, s.counts, s.chunks
    x, v, scalars, limits, start, index, reference = (
        args.x,
        args.v,
        args.scalars,
        args.limits,
        args.start,
        args.index,
        args.reference,
    )
    row = team.ROW + team.WIDTH * p + team.WORDS
    while True:
        j = team.claim(ctl, p)
        if j < 0:
            return
        kind, h, step, done = ctl[row], ctl[row + 1], ctl[row + 2], ctl[row + 3]
        n = x.shape[0]
        if kind == UPDATE:
            groups = (args.powered.shape[0] + 2) // 3
            if j < groups:  # the channels' powers, from the velocities before the update (kept in hist_v[h])
                block = args.block
                power_group(
                    block.reshape(block.shape[0], 3 * n),
                    args.hist_v[h].reshape(-1),
                    args.powered,
                    args.hist_p[h],
                    3 * j,
                )
                team.finish(ctl, p)
                continue
            j -= groups
        if kind == BRAKES:
            split_brakes(
                x,
                v,
                args.dt,
                scalars,
                args.decay_walls,
                args.decay_poles,
                args.source,
                start,
                args.before,
                args.after,
                args.brake_work,
                args.brake_hit,
                counts,
                s.pair_k,
                s.pair_l,
                chunks,
                done,
            )
            team.finish(ctl, p)
            continue
        r0, r1, t0, t1 = block_rows(j, chunks, n)
        if kind == DUE:
            partial[j, P_DUE] = max_displacement2(x[t0:t1], reference[t0:t1])
        elif kind == FORCES:
            forces(
                x,
                v,
                args.hist_v[h],
                args.hist_a[h],
                args.length,
                args.exact_bond,
                args.block,
                args.total,
                args.channel,
                args.tip_charge,
                args.rod_charge,
                scalars,
                args.plasma,
                args.source,
                args.source_charge,
                args.line,
                args.nodes,
                args.weights,
                args.held,
                args.tip_far,
                args.tip_fast,
                args.rate,
                args.base,
                args.base_step,
                args.extrapolate,
                args.lists,
                start,
                index,
                args.centre,
                args.centre_force,
                args.save_x,
                args.save_v,
                s.zero,
                step,
                done,
                r0,
                r1,
                t0,
                t1,
            )
        elif kind == UPDATE:
            partial[j, P_BOND] = ab4_rods(
                x, v, args.hist_v, args.hist_a, args.slot_table[h], args.dt, args.length, r0, r1
            )
            if scalars[SC_TIP_BRAKE_SPLIT] != 0.0:
                partial[j, P_DUE_SPLIT] = max_displacement2(x[t0:t1], reference[t0:t1])
        elif kind == UNDO:
            _copy_rows(x, args.save_x, t0, t1)
            _copy_rows(v, args.save_v, t0, t1)
        elif kind == PAIRS:
            counts[j, 0] = close_pairs_rows(x, start, index, scalars[SC_RSTAR], t0, t1, s.pair_k, s.pair_l, start[t0])
        elif kind == CONSTRAIN:
            length = args.length
            ell = length if length.shape[0] == 0 else length[r0:r1]
            err, speed = _constrain_bonds_checked(x[t0:t1], v[t0:t1], args.project, args.correct_velocity, ell)
            partial[j, P_BOND_AFTER] = err
            partial[j, P_SPEED] = speed
            if args.lists[2] and limits[LIM_NETWORK] == 1.0:
                partial[j, P_DUE_AFTER] = max_displacement2(x[t0:t1], reference[t0:t1])
        elif kind == CONTACTS:
            m = args.pairs.shape[0]
            ok, n_known, n_close = contacts_part(
                x,
                start,
                index,
                args.pairs,
                j * m // chunks,
                (j + 1) * m // chunks,
                t0,
                t1,
                scalars[SC_RSTAR],
                scalars[SC_RELEASE],
                limits[LIM_CATHODE_Z],
                limits[LIM_ANODE_Z],
                args.on_cathode,
                args.on_anode,
                limits[LIM_FILAMENT_R],
                args.on_filament,
            )
            counts[j, 1] = 1 if ok else 0
            counts[j, 2] = n_known
            counts[j, 3] = n_close
        team.finish(ctl, p)


@njit
def forces(
    x,
    v,
    hist_vh,
    hist_ah,
    length,
    exact_bond,
    block,
    total,
    channel,
    tip_charge,
    rod_charge,
    scalars,
    plasma,
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
    centre,
    centre_force,
    save_x,
    save_v,
    zero,
    step,
    done,
    r0,
    r1,
    t0,
    t1,
):
    """The forces of a step on the rods ``r0`` to ``r1`` (tips ``t0`` to ``t1``), each term into its
    channel, their sum and the accelerations into ``hist_ah``, the velocities into ``hist_vh``
    (``ForceField.evaluate`` with ``full=False``, ``MultipleTimeStepping.complete``, then
    ``AdamsBashforth4.step`` up to the update)."""
    amb_k, rstar, kappa, tb_k = scalars[SC_AMBIENT_K], scalars[SC_RSTAR], scalars[SC_KAPPA], scalars[SC_TIP_BRAKE_K]
    z_c, z_a, wall_k = scalars[SC_CATHODE_Z], scalars[SC_ANODE_Z], scalars[SC_WALL_K]
    fil_current, fil_w, pole_k = scalars[SC_FILAMENT_CURRENT], scalars[SC_FILAMENT_W], scalars[SC_POLE_K]
    r_in, r_out = scalars[SC_FAST_INNER], scalars[SC_FAST_OUTER]
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
    if lists[1]:
        _copy_rows(save_x, x, t0, t1)
        _copy_rows(save_v, v, t0, t1)
    _copy_rows(hist_vh, v, t0, t1)
    # the fast terms, each into its channel; the constant channels (uniform field, electric field,
    # the split tip brake's zeros) keep their values
    xs, vs, qs = x[t0:t1], v[t0:t1], tip_charge[t0:t1]
    if c_tb >= 0 and tb_k == tb_k:
        tip_brake_rows(x, v, start, index, rstar, tb_k, t0, t1, block[c_tb])
    # the element-wise loops over flat slices: over (n, 3) slices they were 1.5 times slower than over the
    # whole arrays, flat 2.4 times faster (the extrapolation of 3 held forces, 2400 tips, Zen 5)
    e0, e1 = 3 * t0, 3 * t1
    if c_amb >= 0:
        out, vf = block[c_amb].reshape(-1)[e0:e1], v.reshape(-1)[e0:e1]
        for i in range(e1 - e0):
            out[i] = vf[i] * -amb_k
    if c_pl >= 0:
        _plasma_force_on_tips(xs, qs, plasma[0], plasma[1], plasma[2], plasma[3], block[c_pl][t0:t1])
    if c_wall >= 0:
        _electrode_walls(xs, vs, z_c, z_a, rstar, kappa, wall_k, block[c_wall][t0:t1], block[c_wb][t0:t1])
    if c_fil >= 0:
        _filament_force_on_tips(xs, qs, fil_current, fil_w, block[c_fil][t0:t1])
    if c_pole >= 0:
        _monopoles_on_tips(
            xs, vs, qs, source, source_charge, rstar, kappa, pole_k, block[c_pole][t0:t1], block[c_pb][t0:t1]
        )
    if c_line >= 0:  # -1 also when the line charge is slow (held with the slow forces)
        for i in range(r0, r1):
            for d in range(3):
                centre[i, d] = 0.5 * (x[2 * i, d] + x[2 * i + 1, d])
        _line_yukawa_on_centres(
            centre[r0:r1],
            rod_charge[r0:r1],
            line[0],
            line[1],
            line[2],
            line[3],
            line[4],
            nodes,
            weights,
            centre_force[r0:r1],
        )
        out = block[c_line]
        for i in range(r0, r1):
            for d in range(3):
                out[2 * i, d] = 0.5 * centre_force[i, d]
                out[2 * i + 1, d] = 0.5 * centre_force[i, d]
    # MultipleTimeStepping.complete: the tip-tip fast part, the held forces extrapolated
    if c_tip >= 0:
        tip_tip_fast_rows(x, tip_charge, start, index, rstar, kappa, r_in, r_out, t0, t1, tip_fast)
    for j in range(held.shape[0] if extrapolate else 0):
        if base_step[j] < 0 or (zero[j] and done > 0):
            continue
        s = float(step - base_step[j])
        o = (tip_far if held[j] < 0 else block[held[j]]).reshape(-1)[e0:e1]
        r, b = rate[j].reshape(-1)[e0:e1], base[j].reshape(-1)[e0:e1]
        for i in range(e1 - e0):
            o[i] = r[i] * s + b[i]
    if c_tip >= 0:
        out, far, fast = block[c_tip].reshape(-1)[e0:e1], tip_far.reshape(-1)[e0:e1], tip_fast.reshape(-1)[e0:e1]
        for i in range(e1 - e0):
            out[i] = far[i] + fast[i]
    sum_rows_range(total.reshape(-1), block.reshape(block.shape[0], 3 * x.shape[0]), e0, e1)
    # AdamsBashforth4.step: the accelerations with the bond force
    _bond_acceleration(total[t0:t1], vs, xs, exact_bond, hist_ah[t0:t1])


@njit
def split_brakes(
    x,
    v,
    dt,
    scalars,
    decay_walls,
    decay_poles,
    source,
    start,
    before,
    after,
    brake_work,
    brake_hit,
    counts,
    pair_k,
    pair_l,
    chunks,
    done,
):
    """The split brakes of step ``done`` of the call, one after another, each over all tips (the pairs of
    the tip brake as the blocks of ``brakes.py::close_pairs_rows`` found them, in order)."""
    rstar, tb_split = scalars[SC_RSTAR], scalars[SC_TIP_BRAKE_SPLIT]
    z_c, z_a = scalars[SC_CATHODE_Z], scalars[SC_ANODE_Z]
    wall_split, pole_split = scalars[SC_WALL_SPLIT], scalars[SC_POLE_SPLIT]
    n = x.shape[0]
    if tb_split != 0.0:
        w = 0.0
        m = 0
        for c in range(chunks):
            t0 = block_rows(c, chunks, n)[2]
            w = brake_found_pairs(v, pair_k, pair_l, start[t0], counts[c, 0], tb_split, dt, w)
            m += counts[c, 0]
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
