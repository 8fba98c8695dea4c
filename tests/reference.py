"""Slow, obviously-correct references for the engine kernels (pure numpy / Python loops).

Each follows docs/model.md 'Force terms' or 'Rigid rods and time integration' literally; the kernels must agree with them
to round-off.
"""

import math
from collections import defaultdict
from itertools import combinations

import numpy as np
import scipy.integrate


def tip_law(r, p, rstar, kappa):
    """f(r) of term 1 (positive = repulsive)."""
    if r >= rstar:
        return p / r**2
    return p * r / rstar**3 + kappa * (rstar - r) / rstar**3


def tip_law_potential(r, p, rstar, kappa):
    if r >= rstar:
        return p / r
    return p * (3 * rstar**2 - r**2) / (2 * rstar**3) + kappa * (rstar - r) ** 2 / (2 * rstar**3)


def tip_tip_force(position, charge, rstar, kappa):
    n = len(position)
    out = np.zeros((n, 3))
    for k in range(n):
        for l in range(n):
            if k // 2 == l // 2:
                continue
            d = position[k] - position[l]
            r = np.linalg.norm(d)
            if r > 0:
                out[k] += tip_law(r, charge[k] * charge[l], rstar, kappa) * d / r
    return out


def tip_tip_energy(position, charge, rstar, kappa):
    n = len(position)
    return sum(
        tip_law_potential(np.linalg.norm(position[k] - position[l]), charge[k] * charge[l], rstar, kappa)
        for k in range(n)
        for l in range(k + 1, n)
        if k // 2 != l // 2
    )


def tip_brake(position, velocity, rstar, k_br):
    n = len(position)
    out = np.zeros((n, 3))
    for k in range(n):
        for l in range(n):
            if k // 2 != l // 2 and np.linalg.norm(position[k] - position[l]) < rstar:
                out[k] -= k_br * (velocity[k] - velocity[l])
    return out


def _yukawa_f(r, zz, screening, core):
    """Term 6 magnitude; inside the core radius it falls linearly, f(r_c) r / r_c."""
    if r < core:
        return _yukawa_f(core, zz, screening, 0.0) * r / core
    return zz * math.exp(-r / screening) * (1 / r**2 + 1 / (screening * r))


def _yukawa_u(r, zz, screening, core):
    if r < core:
        return _yukawa_u(core, zz, screening, 0.0) + _yukawa_f(core, zz, screening, 0.0) * (core**2 - r**2) / (2 * core)
    return zz * math.exp(-r / screening) / r


def yukawa_force(centre, z, screening, cutoff, core=0.0):
    n = len(centre)
    out = np.zeros((n, 3))
    for i in range(n):
        for j in range(n):
            d = centre[i] - centre[j]
            r = np.linalg.norm(d)
            if i != j and r < cutoff:
                out[i] += _yukawa_f(r, z[i] * z[j], screening, core) * d / r
    return out


def yukawa_energy(centre, z, screening, cutoff, core=0.0):
    n = len(centre)
    total = 0.0
    for i in range(n):
        for j in range(i + 1, n):
            r = np.linalg.norm(centre[i] - centre[j])
            if r < cutoff:
                zz = z[i] * z[j]
                total += _yukawa_u(r, zz, screening, core) - _yukawa_u(cutoff, zz, screening, core)
    return total


def plasma_field(point, x0, y0, radius, current):
    out = np.zeros_like(point)
    for k, p in enumerate(point):
        dx, dy = p[0] - x0, p[1] - y0
        rho = math.hypot(dx, dy)
        mag = 2 * current * rho / radius**2 if rho <= radius else 2 * current / rho
        if rho > 0:
            out[k] = mag * np.array([-dy / rho, dx / rho, 0.0])
    return out


def electrode_walls(position, velocity, z_lo, z_hi, rstar, kappa, k_br):
    push = np.zeros_like(position)
    brake = np.zeros_like(position)
    for k, (p, v) in enumerate(zip(position, velocity)):
        for h, sign in ((p[2] - z_lo, +1.0), (z_hi - p[2], -1.0)):
            if h < rstar:
                push[k, 2] += sign * kappa * (rstar - h) / rstar**3
                brake[k] -= k_br * v
    return push, brake


def bond_acceleration(force, velocity, position, exact):
    """Paper Eqs. (5-6) with A from docs/model.md 'Rigid rods and time integration' (exact) or paper Eq. (9)."""
    out = np.empty_like(force)
    for i in range(len(position) // 2):
        a, b = 2 * i, 2 * i + 1
        r12 = position[a] - position[b]
        v12 = velocity[a] - velocity[b]
        G = force[a] - force[b]
        A = 0.5 * (G @ r12 + (v12 @ v12 if exact else 0.0)) / (r12 @ r12)
        out[a] = force[a] - A * r12
        out[b] = force[b] + A * r12
    return out


def constrain_bonds(position, velocity, project, correct_velocity, length=None):
    x, v = position.copy(), velocity.copy()
    for i in range(len(x) // 2):
        a, b = 2 * i, 2 * i + 1
        ell = 1.0 if length is None else length[i]
        if project:
            c = 0.5 * (x[a] + x[b])
            u = (x[a] - x[b]) / np.linalg.norm(x[a] - x[b])
            x[a], x[b] = c + 0.5 * ell * u, c - 0.5 * ell * u
        if correct_velocity:
            r12 = x[a] - x[b]
            vc = -((v[a] - v[b]) @ r12) / (2 * (r12 @ r12))  # solves paper Eq. (15)
            v[a], v[b] = v[a] + vc * r12, v[b] - vc * r12
    return x, v


# ----------------------------------------------------------------------------- topology
# The topology and tip merge as computed before the array kernels (scipy.sparse.csgraph and
# networkx): the oracle lives in the package, where the benchmarks time the kernels against it.
import networkx as nx  # noqa: E402

from selfas_graph.bench.oracles import (  # noqa: E402,F401
    classify_rods_scipy_networkx,
    component_labels_scipy,
    merge_tips_scipy,
)

# ----------------------------------------------------------------------------- rod currents
# docs/model.md 'Term 9', 'Term 10': the segment field in the textbook form (perpendicular foot,
# cosines of the end angles), sums with explicit loops, forces with np.cross.


def segment_field(x, A, B, J, w):
    """Finite-wire field, textbook form: (J rho / (rho^2 + w^2)) (cos t1 - cos t2) phi_hat.

    rho is the distance of x to the line AB, phi_hat = s_hat x rho_hat, cos t1 and
    cos t2 the cosines of the angles between s_hat and x - A, x - B.
    """
    x, A, B = (np.asarray(v, dtype=float) for v in (x, A, B))
    s = B - A
    L = np.linalg.norm(s)
    if L == 0.0:
        return np.zeros(3)
    sh = s / L
    a = x - A
    b = x - B
    rho_vec = a - np.dot(a, sh) * sh
    rho = np.linalg.norm(rho_vec)
    if rho == 0.0 or np.linalg.norm(a) == 0.0 or np.linalg.norm(b) == 0.0:
        return np.zeros(3)
    phi = np.cross(sh, rho_vec / rho)
    cos1 = np.dot(sh, a) / np.linalg.norm(a)
    cos2 = np.dot(sh, b) / np.linalg.norm(b)
    return J * rho / (rho**2 + w**2) * (cos1 - cos2) * phi


def segment_vector_potential(x, A, B, J):
    """Vector potential of a finite wire, closed form: ``J s_hat ln((|a| + s_hat.a) / (|b| + s_hat.b))``
    (``a = x - A``, ``b = x - B``; the integral of ``J dl / |x - x'|`` along the wire), whose curl
    is :func:`segment_field` with ``w = 0`` (docs/model.md 'The rod currents by a tree')."""
    x, A, B = (np.asarray(v, dtype=float) for v in (x, A, B))
    s = B - A
    sh = s / np.linalg.norm(s)
    a, b = x - A, x - B
    return J * sh * np.log((np.linalg.norm(a) + sh @ a) / (np.linalg.norm(b) + sh @ b))


def rod_current_field(points, exclude, position, active, current, w):
    """Field of the active rods at each point, skipping exclude[p], by explicit loops."""
    out = np.zeros((len(points), 3))
    for p, x in enumerate(points):
        for j in active:
            if j == exclude[p]:
                continue
            out[p] += segment_field(x, position[2 * j], position[2 * j + 1], current[j], w)
    return out


def quadrature_points(position, active, t):
    """x_a + t s for each active rod (rod-major rows)."""
    rows = []
    for j in active:
        xa, xb = position[2 * j], position[2 * j + 1]
        for tg in t:
            rows.append(xa + tg * (xb - xa))
    return np.array(rows).reshape(-1, 3)


def lorentz_force_on_rods(position, active, current, field, t, wts):
    """Tip forces from J w_g (s x B_g), shared (1 - t_g) to tip a and t_g to tip b."""
    out = np.zeros_like(position)
    n_gl = len(t)
    for r, j in enumerate(active):
        s = position[2 * j + 1] - position[2 * j]
        for g in range(n_gl):
            dF = current[j] * wts[g] * np.cross(s, field[r * n_gl + g])
            out[2 * j] += (1.0 - t[g]) * dF
            out[2 * j + 1] += t[g] * dF
    return out


def closest_parameter(A, s, C, u):
    """(t, d) of the closest points of segments A + t s and C + v u: minimise over the square
    [0, 1]^2 by its interior stationary point and the four edges (each a clamped 1-D minimum)."""
    A, s, C, u = (np.asarray(v, dtype=float) for v in (A, s, C, u))

    def dist(t, v):
        return float(np.linalg.norm(A + t * s - C - v * u))

    cands = []
    M = np.array([[s @ s, -(s @ u)], [-(s @ u), u @ u]])
    rhs = np.array([-(s @ (A - C)), u @ (A - C)])
    if abs(np.linalg.det(M)) > 1e-12 * (s @ s) * (u @ u):
        t, v = np.linalg.solve(M, rhs)
        if 0 <= t <= 1 and 0 <= v <= 1:
            cands.append((dist(t, v), t))
    for v in (0.0, 1.0):  # edges v fixed: t minimises |A + t s - (C + v u)|
        t = min(max(-(s @ (A - C - v * u)) / (s @ s), 0.0), 1.0) if s @ s > 0 else 0.0
        cands.append((dist(t, v), t))
    for t in (0.0, 1.0):  # edges t fixed
        v = min(max((u @ (A + t * s - C)) / (u @ u), 0.0), 1.0) if u @ u > 0 else 0.0
        cands.append((dist(t, v), t))
    d, t = min(cands)
    return t, d


def near_rule(A, s, C, u, h_min, panel_t, panel_w, gl_t, gl_w, t_star):
    """Nodes and weights of the near rule of term 10 (kernels/currents.py 'near pairs'), from its
    description: panels from t_star to each end, each as long as the distance from its inner
    edge to segment C + v u (in rod lengths), at least h_min, at most twice the one before
    (after 53 panels on a side, twice the one before), 4-point Gauss-Legendre on each; then the
    plain rule with negative weights."""
    A, s, C, u = (np.asarray(v, dtype=float) for v in (A, s, C, u))
    length = np.linalg.norm(s)

    def gap(t):  # distance from A + t s to the segment, in rod lengths
        p = A + t * s
        v = min(max((p - C) @ u / (u @ u), 0.0), 1.0)
        return np.linalg.norm(p - C - v * u) / length

    nodes, weights = [], []
    for direction in (+1, -1):
        edge, h, count = t_star, max(gap(t_star), h_min), 0
        while (edge < 1.0) if direction > 0 else (edge > 0.0):
            other = min(edge + h, 1.0) if direction > 0 else max(edge - h, 0.0)
            lo, hi = min(edge, other), max(edge, other)
            nodes += list(lo + (hi - lo) * np.asarray(panel_t))
            weights += list((hi - lo) * np.asarray(panel_w))
            edge = other
            count += 1
            h = min(2 * h, max(gap(edge), h_min)) if count < 53 else 2 * h
    return np.array(nodes + list(gl_t)), np.array(weights + [-w for w in gl_w])


def lorentz_near_correction(position, active, current, rows, gl_t, gl_w, panel_t, panel_w, w):
    """Tip forces of the near-pair correction: for each active rod i and each j in rows[i], the
    force of j's field on i's current by the near rule less the plain rule, shared (1 - t) to
    tip a and t to tip b."""
    out = np.zeros_like(position)
    for i, near in rows.items():
        A, B = position[2 * i], position[2 * i + 1]
        s = B - A
        h_min = max(0.5 * w / np.linalg.norm(s), 2.0**-10)
        for j in near:
            C, E = position[2 * j], position[2 * j + 1]
            t_star, _ = closest_parameter(A, s, C, E - C)
            nodes, weights = near_rule(A, s, C, E - C, h_min, panel_t, panel_w, gl_t, gl_w, t_star)
            for t, wt in zip(nodes, weights):
                dF = current[i] * wt * np.cross(s, segment_field(A + t * s, C, E, current[j], w))
                out[2 * i] += (1 - t) * dF
                out[2 * i + 1] += t * dF
    return out


# ----------------------------------------------------------------------------- neighbour lists


def neighbour_pairs(x, r, exclude_same_rod):
    """Every pair (i < j) of points closer than r, by all distances (of different rods if asked)."""
    d = np.linalg.norm(x[:, None] - x[None], axis=-1)
    i, j = np.nonzero(np.triu(d < r, 1))
    keep = (i // 2 != j // 2) if exclude_same_rod else np.ones(len(i), bool)
    return set(zip(i[keep].tolist(), j[keep].tolist()))


def rows_in_cell_order(start, index, order):
    """Compressed rows renumbered by the permutation ``order``: row t is the row of point
    ``order[t]``, in the same order, each neighbour l written as its place in ``order``."""
    place = np.empty(len(order), dtype=np.int64)
    place[order] = np.arange(len(order))
    rows = [place[index[start[k] : start[k + 1]]] for k in order]
    new_start = np.concatenate([[0], np.cumsum([len(r) for r in rows])]).astype(np.int64)
    return new_start, (np.concatenate(rows) if rows else np.zeros(0, np.int64)).astype(np.int64)


# ----------------------------------------------------------------------------- external objects


def line_yukawa_force(p, z1, z2, lam, R, w, Z=1.0):
    """Direct numerical integral of the screened line-charge force (scipy.quad, tight tolerances)."""

    def comp(i):
        def integrand(zl):
            d = np.array([p[0], p[1], p[2] - zl])
            r = math.sqrt(d @ d + w * w)
            return Z * lam * math.exp(-r / R) * (1 / r**2 + 1 / (R * r)) * d[i] / r

        return scipy.integrate.quad(
            integrand, z1, z2, epsabs=1e-14, epsrel=1e-11, limit=400, points=[p[2]] if z1 < p[2] < z2 else None
        )[0]

    return np.array([comp(i) for i in range(3)])


def line_yukawa_energy(p, z1, z2, lam, R, w, Z=1.0):
    """Direct numerical integral of the screened line charge's potential energy, ``Z lam int exp(-r/R) / r dz``
    with ``r^2 = rho^2 + w^2 + (z_p - z)^2`` (scipy.quad, tight tolerances); minus its gradient is
    :func:`line_yukawa_force`."""

    def integrand(zl):
        r = math.sqrt(p[0] ** 2 + p[1] ** 2 + w * w + (p[2] - zl) ** 2)
        return Z * lam * math.exp(-r / R) / r

    return scipy.integrate.quad(
        integrand, z1, z2, epsabs=1e-14, epsrel=1e-11, limit=400, points=[p[2]] if z1 < p[2] < z2 else None
    )[0]


# ----------------------------------------------------------------------------- filament rule, literally
# docs/model.md 'Connectivity graph and topology' on netlists, with networkx: every simple path
# (exponential, small graphs only) and the biconnected-component rule without reductions.


def merged_labels(n_tips, tip_contacts):
    """Merged node of each tip, by networkx connected components."""
    ideal = nx.Graph()
    ideal.add_nodes_from(range(n_tips))
    ideal.add_edges_from(map(tuple, np.asarray(tip_contacts).tolist()))
    label = np.empty(n_tips, dtype=np.int64)
    for k, comp in enumerate(nx.connected_components(ideal)):
        label[list(comp)] = k
    return label


def attached_labels(n_rods, tip_contacts, conductor_tip, key):
    """Electrical node of each tip: its merged node, or ``("att", k)`` when the merged node
    touches conductors of exactly one key k (ideal contacts pin it to that conductor)."""
    m = merged_labels(2 * n_rods, tip_contacts).tolist()
    keys = defaultdict(set)
    for t, k in zip(np.asarray(conductor_tip).tolist(), np.asarray(key).tolist()):
        keys[m[t]].add(k)
    return [("att", next(iter(keys[x]))) if len(keys[x]) == 1 else x for x in m]


def brute_force_filament(n_rods, tip_contacts, conductor_tip, key):
    """Rods on some simple path between two different attachments: enumerate all paths.

    The definition of docs/model.md 'Connectivity graph and topology' taken literally, on a MultiGraph (parallel
    rods are separate edges); exponential, so only for small graphs.
    """
    m = attached_labels(n_rods, tip_contacts, conductor_tip, key)
    g = nx.MultiGraph()
    for i in range(n_rods):
        g.add_edge(m[2 * i], m[2 * i + 1], key=("rod", i))
    for j, (t, k) in enumerate(zip(np.asarray(conductor_tip).tolist(), np.asarray(key).tolist())):
        if m[t] != ("att", k):
            g.add_edge(m[t], ("att", k), key=("contact", j))
    atts = sorted({("att", k) for k in np.asarray(key).tolist()})
    on_path = np.zeros(n_rods, dtype=bool)
    for a1, a2 in combinations(atts, 2):
        for path in nx.all_simple_edge_paths(g, a1, a2):
            for _, _, (kind, i) in path:
                if kind == "rod":
                    on_path[i] = True
    return on_path


def rule_filament(n_rods, tip_contacts, conductor_tip, key):
    """The biconnected-component rule applied literally with networkx (no reductions)."""
    m = attached_labels(n_rods, tip_contacts, conductor_tip, key)
    g = nx.Graph()
    g.add_edges_from((m[2 * i], m[2 * i + 1]) for i in range(n_rods) if m[2 * i] != m[2 * i + 1])
    for t, k in zip(np.asarray(conductor_tip).tolist(), np.asarray(key).tolist()):
        if m[t] != ("att", k):
            g.add_edge(m[t], ("att", k))
        g.add_edge(("att", k), "X")
    in_x = set()
    if "X" in g:
        for block in nx.biconnected_component_edges(g):
            if any("X" in e for e in block):
                in_x |= {frozenset(e) for e in block}
    return np.array([frozenset((m[2 * i], m[2 * i + 1])) in in_x for i in range(n_rods)])


# ----------------------------------------------------------------------------- per-step glue


def channel_sum(channels):
    """Sum of the force channels, element by element, in channel order starting from 0.0."""
    n_ch, n, _ = channels.shape
    out = np.zeros((n, 3))
    for k in range(n):
        for c in range(3):
            acc = 0.0
            for j in range(n_ch):
                acc = acc + float(channels[j, k, c])
            out[k, c] = acc
    return out


def extrapolate(rate, base, steps):
    """Linear extrapolation ``rate * steps + base`` of a held force, element by element."""
    out = np.empty_like(base)
    for k in range(len(base)):
        for c in range(3):
            out[k, c] = float(rate[k, c]) * steps + float(base[k, c])
    return out


def brake_close_pairs(position, velocity, radius, k_br, dt, exclude_same_rod=True):
    """The split brake of docs/model.md 'Rigid rods and time integration', by all distances: every
    pair k < l (of different rods) closer than ``radius``, in (k, l) order, relaxed exactly over dt.
    Returns (velocity after, work, pairs braked)."""
    v = [list(map(float, row)) for row in velocity]
    decay = math.exp(-2.0 * k_br * dt)
    work, m = 0.0, 0
    for k, l in sorted(neighbour_pairs(position, radius, exclude_same_rod)):
        rel2 = 0.0
        for d in range(3):
            diff = v[k][d] - v[l][d]
            rel2 += diff * diff
            mean = 0.5 * (v[k][d] + v[l][d])
            v[k][d], v[l][d] = mean + 0.5 * diff * decay, mean - 0.5 * diff * decay
        work -= 0.25 * (1.0 - decay * decay) * rel2
        m += 1
    return np.array(v).reshape(velocity.shape), work, m


def electrode_brake(position, velocity, z_lo, z_hi, rstar, k_br, dt):
    """The exact electrode brake: a tip within r* of n planes has dv/dt = -n k_br v over dt.
    Returns (velocity after, change of kinetic energy)."""
    touching = [int(p[2] - z_lo < rstar) + int(z_hi - p[2] < rstar) for p in position]
    return _brake_touching(velocity, touching, k_br, dt)


def _brake_touching(velocity, touching, k_br, dt):
    """The exact brake of tips each touching ``touching[k]`` fixed objects: ``v exp(-n k_br dt)``;
    returns (velocity after, change of kinetic energy)."""
    v = np.array(velocity, dtype=float)
    work = 0.0
    for k, n in enumerate(touching):
        if n:
            e0 = 0.5 * float(v[k] @ v[k])
            v[k] = v[k] * math.exp(-n * k_br * dt)
            work += 0.5 * float(v[k] @ v[k]) - e0
    return v, work


def monopole_brake(position, velocity, source, rstar, k_br, dt):
    """The exact brake of fixed monopoles on tips (term 11 with term 2's brake; a monopole does not
    move): a tip within r* of n of ``source`` has dv/dt = -n k_br v over dt. Returns (velocity after,
    change of kinetic energy)."""
    touching = [sum(int(np.linalg.norm(p - s) < rstar) for s in source) for p in position]
    return _brake_touching(velocity, touching, k_br, dt)


def monopoles_energy(position, charge, source, source_charge, rstar, kappa):
    """Energy of tips among fixed monopoles: term 1's potential of every tip-source pair (math.fsum)."""
    return math.fsum(
        tip_law_potential(float(np.linalg.norm(p - s)), float(q) * float(Q), rstar, kappa)
        for p, q in zip(position, charge)
        for s, Q in zip(source, source_charge)
    )


def monopole_field(point, source, source_charge, rstar):
    """B of fixed monopoles: ``Q d / r^3``, and ``Q d / r*^3`` inside r* (the charge smeared over a ball)."""
    out = np.zeros((len(point), 3))
    for k, p in enumerate(point):
        for s, Q in zip(source, source_charge):
            d = p - s
            r = float(np.linalg.norm(d))
            out[k] += Q * d / (r**3 if r >= rstar else rstar**3)
    return out


def electrode_energy(position, z_lo, z_hi, rstar, kappa):
    """Elastic energy of the electrode planes (term 8): ``kappa (r* - h)^2 / (2 r*^3)`` for each tip
    and plane at height ``h < r*`` from it (h < 0 beyond the plane)."""
    terms = []
    for p in position:
        for h in (p[2] - z_lo, z_hi - p[2]):
            if h < rstar:
                terms.append(kappa * (rstar - h) ** 2 / (2 * rstar**3))
    return math.fsum(terms)


def uniform_force(charge, B):
    """Term 4, q_k B, tip by tip."""
    return np.array([[float(q) * float(b) for b in B] for q in charge]).reshape(len(charge), 3)


def dot(a, b):
    """``sum_i a_i b_i`` over all elements, correctly rounded (math.fsum of the products)."""
    return math.fsum(float(p) * float(q) for p, q in zip(np.ravel(a), np.ravel(b)))


def ab4_step(x, v, hist_v, hist_a, slots, dt, length=None):
    """Adams-Bashforth 4 on positions and velocities, element by element, and the largest bond-length
    error of the new positions. Returns (x, v, error)."""
    x, v = np.array(x, dtype=float), np.array(v, dtype=float)
    c = dt / 24.0
    for y, hist in ((x, hist_v), (v, hist_a)):
        d0, d1, d2, d3 = (hist[s] for s in slots)
        for k in range(len(y)):
            for j in range(3):
                y[k, j] = y[k, j] + c * (55.0 * d0[k, j] - 59.0 * d1[k, j] + 37.0 * d2[k, j] - 9.0 * d3[k, j])
    return x, v, bond_length_error(x, length)


def bond_length_error(x, length=None):
    """Largest ``| |x_a - x_b| - l_i |`` over the rods."""
    worst = 0.0
    for i in range(len(x) // 2):
        ell = 1.0 if length is None else float(length[i])
        worst = max(worst, abs(math.sqrt(sum(float(r) ** 2 for r in x[2 * i] - x[2 * i + 1])) - ell))
    return worst
