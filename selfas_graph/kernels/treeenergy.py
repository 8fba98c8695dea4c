"""Tip-tip potential energy by the tip tree (docs/model.md 'Term 1'): the energy of a frame for
large systems, where the direct sum (:func:`.tips.tip_tip_energy`, O(N^2)) costs more than the
steps between two frames.

For each target group (in parallel over groups, a group writing only the rows of its own tips) one
walk of the tree with the acceptance test of the force (:mod:`.treewalk`): a cell whose radius is
below the opening angle times its distance from the group's box, and none of whose tips can be
within r* of the box, acts through the potential of its moments
(:func:`.multipole.potential_hexadecapole`, float64); the other leaves are near and their tips are
summed exactly with the pair law (:func:`.laws.tip_potential`), the tips of the target's own rod
left out. When the target's rod partner sits in an accepted cell, its Coulomb term ``q_k q_p / r``
(exact there: the cell's tips are all beyond r*) is taken out of the moments' sum.

Row k holds ``E_k = (1/2) sum_l U(r_kl)`` over the tips l of other rods, so that the rows add up to
the energy with each pair counted once; one value per row keeps the total independent of how the
groups are split over threads or ranks. With ``theta = 0`` no cell is accepted and every row is the
exact sum; otherwise the rows carry the tree's truncation error (measured in docs/performance.md
'The energy of a frame by the tree').
"""

import math

import numpy as np

from ._jit import njit_parallel_sum, prange
from .laws import tip_potential
from .multipole import potential_hexadecapole
from .treewalk import accepts, append_grown


@njit_parallel_sum
def tree_energy_groups(
    x, y, z, charge, rod, index, rank, start, end, nxt, box, centre, radius, moment, group, theta, rstar, kappa,
    g_lo, g_hi, out,
):  # fmt: skip
    """Tip-tip energy of the tips of groups ``g_lo..g_hi-1`` by the tree (module docstring).

    Parameters
    ----------
    x, y, z, charge, rod, index, rank, start, end, nxt, box, centre, radius, moment, group :
        The tree (:class:`.tree.TipTree`), as for :func:`.treewalk.evaluate_groups`.
    theta, rstar, kappa : float
        Opening angle, transition radius r* and core stiffness.
    g_lo, g_hi : int
        The groups whose tips are evaluated.
    out : (n_tips,) float64
        ``out[index[i]]`` overwritten with the energy row of each of those tips (original order);
        other rows untouched.
    """
    theta2 = theta * theta
    n_cells = start.shape[0]
    for gi in prange(g_lo, g_hi):
        g = group[gi]
        gs = start[g]
        ge = end[g]
        m = ge - gs
        xl = box[g, 0]
        yl = box[g, 1]
        zl = box[g, 2]
        xh = box[g, 3]
        yh = box[g, 4]
        zh = box[g, 5]
        phi = np.zeros(m)
        near_start = np.empty(64, np.int64)
        near_end = np.empty(64, np.int64)
        n_near = 0
        c = 0
        while c < n_cells:
            take, _ = accepts(centre, radius, c, xl, yl, zl, xh, yh, zh, theta2, rstar)
            if take:
                cx = centre[c, 0]
                cy = centre[c, 1]
                cz = centre[c, 2]
                for t in range(m):
                    i = gs + t
                    phi[t] += potential_hexadecapole(
                        x[i] - cx, y[i] - cy, z[i] - cz,
                        moment[c, 0], moment[c, 1], moment[c, 2], moment[c, 3], moment[c, 4], moment[c, 5],
                        moment[c, 6], moment[c, 7], moment[c, 8], moment[c, 9], moment[c, 10], moment[c, 11],
                        moment[c, 12], moment[c, 13], moment[c, 14], moment[c, 15], moment[c, 16], moment[c, 17],
                        moment[c, 18], moment[c, 19], moment[c, 20], moment[c, 21], moment[c, 22], moment[c, 23],
                        moment[c, 24],
                    )  # fmt: skip
                c = nxt[c]
            elif nxt[c] == c + 1:
                near_start = append_grown(near_start, n_near, start[c])
                near_end = append_grown(near_end, n_near, end[c])
                n_near += 1
                c += 1
            else:
                c += 1
        for t in range(m):
            i = gs + t
            qk = charge[i]
            rk = rod[i]
            near = 0.0
            partner_near = False
            p = rank[index[i] ^ 1]
            for a in range(n_near):
                partner_near |= near_start[a] <= p < near_end[a]
                for j in range(near_start[a], near_end[a]):
                    dx = x[i] - x[j]
                    dy = y[i] - y[j]
                    dz = z[i] - z[j]
                    u = tip_potential(dx * dx + dy * dy + dz * dz, qk * charge[j], rstar, kappa)
                    near += 0.0 if rod[j] == rk else u
            e = near + qk * phi[t]
            if not partner_near:
                # the partner's charge is in an accepted cell's moments, beyond r*: its Coulomb term out
                dx = x[i] - x[p]
                dy = y[i] - y[p]
                dz = z[i] - z[p]
                e -= qk * charge[p] / math.sqrt(dx * dx + dy * dy + dz * dz)
            out[index[i]] = 0.5 * e
