"""The field of a tree cell's Cartesian multipole moments (docs/model.md 'Term 1'), written once for
float64 and float32.

With ``s = x_l - c`` the offset of a tip from the cell's expansion centre (all moments traceless,
only the independent components stored; ``tree.py`` builds them)::

    M = sum q,  P_i = sum q s_i,  Q_ij = sum q (3 s_i s_j - s^2 d_ij),
    O_ijk = sum q (15 s_i s_j s_k - 3 s^2 (s_i d_jk + s_j d_ik + s_k d_ij)),
    H_ijkl = sum q (105 s_i s_j s_k s_l - 15 s^2 (d_ij s_k s_l + 5 more pairings)
                    + 3 s^4 (d_ij d_kl + d_ik d_jl + d_il d_jk))

the field ``E = -grad phi`` of ``phi = sum q / |r - x_l|`` at ``d = r - c`` (R = |d|) is::

    E = d (M / R^3 + 3 P.d / R^5 + 5 dQd / (2 R^7) + 7 O(ddd) / (6 R^9) + 3 H(dddd) / (8 R^11))
        - P / R^3 - Q.d / R^5 - O(dd.) / (2 R^7) - H(ddd.) / (6 R^9)

and the potential itself (the term of order n is ``(d . E_n) / (n + 1)``, a homogeneous function of
degree -(n + 1))::

    phi = M / R + P.d / R^3 + dQd / (2 R^5) + O(ddd) / (6 R^7) + H(dddd) / (24 R^9)

:func:`make_fields` builds the field up to quadrupole, octupole and hexadecapole order, and the
potential, for one float type: every constant of that type, so that the float32 variant (``precision
= "mixed"``, called with the offset and the moments in units of the cell's distance, where every
power of ``1/R`` stays near 1) runs on float32 lanes throughout, and the float64 variant is the
float64 field. Both are built once, at import (``field_quadrupole``, ``field_octupole``,
``field_hexadecapole`` and their ``_f32`` variants; ``potential_hexadecapole``, float64, for the
tree's energy, :mod:`.treeenergy`). The contractions ``Q.d``, ``O(dd.)`` and ``H(ddd.)`` are written
once and shared by the fields and the potential.
"""

import math

import numpy as np

from ._jit import inline_sum


def make_fields(ft):
    """The multipole fields ``(quadrupole, octupole, hexadecapole)`` and the ``potential`` (up to
    hexadecapoles; it returns phi) in the float type ``ft``.

    Each takes the offset ``dx, dy, dz`` from the cell's centre and the moments as scalars in the
    order of :class:`.tree.TipTree`'s ``moment`` row (M, P x y z, Q xx xy xz yy yz, O xxx xxy xxz
    xyy xyz yyy yyz, H xxxx xxxy xxxz xxyy xxyz xyyy xyyz yyyy yyyz), as many as the order uses,
    and returns the field ``(ex, ey, ez)``. All arguments of type ``ft``; the functions are
    inlined into the loops that call them. With ``arcp`` (``inline_sum``) LLVM takes a float32
    ``1/sqrt`` as a reciprocal square root estimate and one Newton step.
    """
    one = ft(1.0)
    half = ft(0.5)
    two = ft(2.0)
    three = ft(3.0)
    five_halves = ft(2.5)
    six = ft(6.0)
    seven_sixths = ft(7.0 / 6.0)
    sixth = ft(1.0 / 6.0)
    three_eighths = ft(0.375)
    twenty_fourth = ft(1.0 / 24.0)

    @inline_sum
    def q_d(dx, dy, dz, qxx, qxy, qxz, qyy, qyz):
        """``u = Q.d``, ``u_i = Q_ij d_j`` (Q_zz = -(Q_xx + Q_yy))."""
        ux = qxx * dx + qxy * dy + qxz * dz
        uy = qxy * dx + qyy * dy + qyz * dz
        uz = qxz * dx + qyz * dy - (qxx + qyy) * dz
        return ux, uy, uz

    @inline_sum
    def o_dd(dx, dy, dz, oxxx, oxxy, oxxz, oxyy, oxyz, oyyy, oyyz):
        """``v = O(dd.)``, ``v_i = O_ijk d_j d_k`` (the three components with two z follow from the traces)."""
        oxzz = -(oxxx + oxyy)
        oyzz = -(oxxy + oyyy)
        ozzz = -(oxxz + oyyz)
        xx = dx * dx
        yy = dy * dy
        zz = dz * dz
        xy = two * dx * dy
        xz = two * dx * dz
        yz = two * dy * dz
        vx = oxxx * xx + oxyy * yy + oxzz * zz + oxxy * xy + oxxz * xz + oxyz * yz
        vy = oxxy * xx + oyyy * yy + oyzz * zz + oxyy * xy + oxyz * xz + oyyz * yz
        vz = oxxz * xx + oyyz * yy + ozzz * zz + oxyz * xy + oxzz * xz + oyzz * yz
        return vx, vy, vz

    @inline_sum
    def h_ddd(dx, dy, dz, h0, h1, h2, h3, h4, h5, h6, h7, h8):
        """``w = H(ddd.)``, ``w_i = H_ijkl d_j d_k d_l`` (``h0..h8`` as in :func:`hexadecapole`; the six
        others follow from the vanishing traces)."""
        hxxzz = -(h0 + h3)
        hxyzz = -(h1 + h5)
        hxzzz = -(h2 + h6)
        hyyzz = -(h3 + h7)
        hyzzz = -(h4 + h8)
        hzzzz = -(hxxzz + hyyzz)
        xxx = dx * dx * dx
        xxy = three * dx * dx * dy
        xxz = three * dx * dx * dz
        xyy = three * dx * dy * dy
        xyz = six * dx * dy * dz
        xzz = three * dx * dz * dz
        yyy = dy * dy * dy
        yyz = three * dy * dy * dz
        yzz = three * dy * dz * dz
        zzz = dz * dz * dz
        wx = h0 * xxx + h1 * xxy + h2 * xxz + h3 * xyy + h4 * xyz + hxxzz * xzz + h5 * yyy + h6 * yyz + hxyzz * yzz
        wx += hxzzz * zzz
        wy = h1 * xxx + h3 * xxy + h4 * xxz + h5 * xyy + h6 * xyz + hxyzz * xzz + h7 * yyy + h8 * yyz + hyyzz * yzz
        wy += hyzzz * zzz
        wz = h2 * xxx + h4 * xxy + hxxzz * xxz + h6 * xyy + hxyzz * xyz + hxzzz * xzz + h8 * yyy + hyyzz * yyz
        wz += hyzzz * yzz + hzzzz * zzz
        return wx, wy, wz

    @inline_sum
    def quadrupole(dx, dy, dz, m, px, py, pz, qxx, qxy, qxz, qyy, qyz):
        """Field of a cell's moments up to quadrupole at offset d from its centre (module docstring)."""
        ir = one / math.sqrt(dx * dx + dy * dy + dz * dz)
        ir2 = ir * ir
        ir3 = ir * ir2
        ir5 = ir3 * ir2
        ir7 = ir5 * ir2
        ux, uy, uz = q_d(dx, dy, dz, qxx, qxy, qxz, qyy, qyz)
        pd = px * dx + py * dy + pz * dz
        dqd = dx * ux + dy * uy + dz * uz
        radial = m * ir3 + three * pd * ir5 + five_halves * dqd * ir7
        return (radial * dx - px * ir3 - ux * ir5, radial * dy - py * ir3 - uy * ir5, radial * dz - pz * ir3 - uz * ir5)

    @inline_sum
    def octupole(dx, dy, dz, m, px, py, pz, qxx, qxy, qxz, qyy, qyz, oxxx, oxxy, oxxz, oxyy, oxyz, oyyy, oyyz):
        """Field of a cell's moments up to octupole at offset d from its centre (module docstring)."""
        ir = one / math.sqrt(dx * dx + dy * dy + dz * dz)
        ir2 = ir * ir
        ir3 = ir * ir2
        ir5 = ir3 * ir2
        ir7 = ir5 * ir2
        ir9 = ir7 * ir2
        ux, uy, uz = q_d(dx, dy, dz, qxx, qxy, qxz, qyy, qyz)
        pd = px * dx + py * dy + pz * dz
        dqd = dx * ux + dy * uy + dz * uz
        vx, vy, vz = o_dd(dx, dy, dz, oxxx, oxxy, oxxz, oxyy, oxyz, oyyy, oyyz)
        dvd = dx * vx + dy * vy + dz * vz
        radial = m * ir3 + three * pd * ir5 + five_halves * dqd * ir7 + seven_sixths * dvd * ir9
        return (
            radial * dx - px * ir3 - ux * ir5 - half * vx * ir7,
            radial * dy - py * ir3 - uy * ir5 - half * vy * ir7,
            radial * dz - pz * ir3 - uz * ir5 - half * vz * ir7,
        )

    @inline_sum
    def hexadecapole(
        dx, dy, dz, m, px, py, pz, qxx, qxy, qxz, qyy, qyz, oxxx, oxxy, oxxz, oxyy, oxyz, oyyy, oyyz,
        h0, h1, h2, h3, h4, h5, h6, h7, h8,
    ):  # fmt: skip
        """Field of a cell's moments up to hexadecapole at offset d from its centre: the octupole
        field plus, with ``w = H(ddd.)``, ``3/8 d (d.w) / R^11 - w / (6 R^9)`` (module docstring).
        ``h0..h8`` are H_xxxx, H_xxxy, H_xxxz, H_xxyy, H_xxyz, H_xyyy, H_xyyz, H_yyyy, H_yyyz; the
        six others follow from the vanishing traces."""
        ex, ey, ez = octupole(
            dx, dy, dz, m, px, py, pz, qxx, qxy, qxz, qyy, qyz, oxxx, oxxy, oxxz, oxyy, oxyz, oyyy, oyyz
        )  # fmt: skip
        wx, wy, wz = h_ddd(dx, dy, dz, h0, h1, h2, h3, h4, h5, h6, h7, h8)
        ir = one / math.sqrt(dx * dx + dy * dy + dz * dz)
        ir2 = ir * ir
        ir9 = ir * ir2 * ir2 * ir2 * ir2
        radial = three_eighths * (dx * wx + dy * wy + dz * wz) * ir9 * ir2
        return (
            ex + radial * dx - sixth * wx * ir9,
            ey + radial * dy - sixth * wy * ir9,
            ez + radial * dz - sixth * wz * ir9,
        )

    @inline_sum
    def potential(
        dx, dy, dz, m, px, py, pz, qxx, qxy, qxz, qyy, qyz, oxxx, oxxy, oxxz, oxyy, oxyz, oyyy, oyyz,
        h0, h1, h2, h3, h4, h5, h6, h7, h8,
    ):  # fmt: skip
        """Potential of a cell's moments up to hexadecapole at offset d from its centre (module
        docstring; moments above a tree's order are zero, so one function serves every order)."""
        ir = one / math.sqrt(dx * dx + dy * dy + dz * dz)
        ir2 = ir * ir
        ir3 = ir * ir2
        ir5 = ir3 * ir2
        ux, uy, uz = q_d(dx, dy, dz, qxx, qxy, qxz, qyy, qyz)
        vx, vy, vz = o_dd(dx, dy, dz, oxxx, oxxy, oxxz, oxyy, oxyz, oyyy, oyyz)
        wx, wy, wz = h_ddd(dx, dy, dz, h0, h1, h2, h3, h4, h5, h6, h7, h8)
        pd = px * dx + py * dy + pz * dz
        dqd = dx * ux + dy * uy + dz * uz
        dvd = dx * vx + dy * vy + dz * vz
        dwd = dx * wx + dy * wy + dz * wz
        return m * ir + pd * ir3 + ir5 * (half * dqd + ir2 * (sixth * dvd + ir2 * twenty_fourth * dwd))

    return quadrupole, octupole, hexadecapole, potential


field_quadrupole, field_octupole, field_hexadecapole, potential_hexadecapole = make_fields(np.float64)
_, field_octupole_f32, field_hexadecapole_f32, _ = make_fields(np.float32)
