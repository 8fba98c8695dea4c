"""The mixed-precision current kernels against the float64 ones on a saved state
(``selfas-graph bench kernels --mixed-error CHECKPOINT``; docs/performance.md 'Rod-current kernels on AVX2')."""

from __future__ import annotations

import types

import numpy as np


def mixed_error(checkpoint):
    """Rows (quantity, median, p99, max, max diff / max force) of the mixed current kernels
    against the float64 ones on the state of ``checkpoint`` (see the module docstring)."""
    from selfas_graph.kernels import currents as kc
    from selfas_graph.kernels import lorentz as kl

    from .profile import load_state

    sim, origin = load_state(types.SimpleNamespace(checkpoint=checkpoint, extra=[], scenario=None, settle=0))
    ff = sim.force_field
    st = sim.state
    ff.bind(st.position, st.velocity)
    act, cur, w, pos = ff.active_rod, ff.current, ff.wire_radius, st.position
    if not len(act):
        raise SystemExit(f"{checkpoint}: no rod carries current in this state")

    def row(name, a, b):
        na = np.linalg.norm(a, axis=1)
        e = np.linalg.norm(a - b, axis=1)[na > 0] / na[na > 0]
        return (name, np.median(e), np.percentile(e, 99), e.max(), np.linalg.norm(a - b, axis=1).max() / na.max())

    rows = []
    f64, f32 = np.zeros_like(pos), np.zeros_like(pos)
    kc.current_force_on_tips(pos, st.tip_charge, act, cur, w, 0, len(pos), f64)
    kc.current_force_on_tips_mixed(pos, st.tip_charge, act, cur, w, 0, len(pos), f32)
    rows.append(row("term 9 force on the tips", f64, f32))
    t, wt = kl.gauss_legendre_01(sim.params.forces.current_lorentz.quadrature_points)
    pts = np.empty((len(act) * len(t), 3))
    kl.quadrature_points(pos, act, t, pts)
    excl = np.repeat(act, len(t))
    b64, b32 = np.empty_like(pts), np.empty_like(pts)
    kc.rod_current_field(pts, excl, pos, act, cur, w, b64)
    kc.rod_current_field_mixed(pts, excl, pos, act, cur, w, b32)
    rows.append(row("rod currents' field at the quadrature points", b64, b32))
    other, extra = np.zeros_like(pts), np.empty_like(pts)
    for source in ff.field_sources:
        source.field_at(pts, extra)
        other += extra
    l64, l32 = np.zeros_like(pos), np.zeros_like(pos)
    kl.lorentz_force_on_rods(pos, act, cur, b64 + other, t, wt, l64)
    kl.lorentz_force_on_rods(pos, act, cur, b32 + other, t, wt, l32)
    rows.append(row("term 10 force (all fields)", l64, l32))
    return origin, len(act), st.n_rods, rows
