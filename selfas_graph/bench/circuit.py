"""Time the topology (``classify_rods``) and the circuit solve (``solve_circuit``).

Usage::

    selfas-graph bench circuit [--sizes 1000 10000 100000] [--repeat 3] [--seed 1]

Networks (all between a cathode at the bottom and an anode at the top, plus
free rods that touch nothing):

* ``lattice``: a diluted simple-cubic bond lattice of junctions; each kept bond is
  one rod (random orientation); the tips meeting at a junction are stuck in a
  chain of tip contacts (a star junction); the junctions of the bottom and top
  layers touch the cathode / anode. 80 % of the rods are in the lattice (bond
  kept with probability 0.7, above the bond-percolation threshold 0.25), 20 %
  are free.
* ``chains``: straight chains of rods spanning the gap, cross-linked at random
  junctions to a neighbouring chain (tip clusters), plus dangling side rods,
  plus 20 % free rods.

Columns: rods (free rods included), contacts (tip-tip plus conductor), rods in
filaments, ``classify_rods`` time, the same topology by the scipy/networkx version the
array kernels replaced (``selfas_graph/bench/oracles.py``, the peer: results checked equal),
``solve_circuit`` time with the default direct solver and with ``solver="cg"``. Each time is
the best of ``--repeat`` runs; the solves are given no memo of the last system
(``circuit.SolveMemo``), so every solve factorises.
"""

from __future__ import annotations

import argparse
import os
import platform
import time

import networkx
import numpy as np
import scipy

from selfas_graph.model.circuit import solve_circuit
from selfas_graph.model.events import CONDUCTOR_ANODE, CONDUCTOR_CATHODE
from selfas_graph.model.graph import classify_rods

from . import oracles
from .peer import machine


def _junction_contacts(junction_of_tip: np.ndarray) -> np.ndarray:
    """Tip contacts that stick all tips sharing a junction id into one chain."""
    order = np.argsort(junction_of_tip, kind="stable")
    j = junction_of_tip[order]
    same = j[1:] == j[:-1]
    return np.stack([order[:-1][same], order[1:][same]], axis=1)


def _finish(n_rods, junction_of_tip, bottom, top, gap):
    """Tip contacts, conductor contacts (one per bottom/top junction), potentials."""
    n_tips = 2 * n_rods
    used = junction_of_tip >= 0
    tips = np.flatnonzero(used)
    contacts = _junction_contacts(junction_of_tip[tips])
    tip_contacts = np.sort(tips[contacts], axis=1).astype(np.int64)
    # first tip at each bottom / top junction touches the electrode
    first = {}
    for is_side, cid in ((bottom, CONDUCTOR_CATHODE), (top, CONDUCTOR_ANODE)):
        t = tips[is_side[junction_of_tip[tips]]]
        _, idx = np.unique(junction_of_tip[t], return_index=True)
        first[cid] = t[idx]
    conductor_tip = np.concatenate([first[CONDUCTOR_CATHODE], first[CONDUCTOR_ANODE]])
    conductor_id = np.concatenate(
        [np.full(first[c].size, c, dtype=np.int64) for c in (CONDUCTOR_CATHODE, CONDUCTOR_ANODE)]
    )
    delta = 1.0
    potential = np.where(conductor_id == CONDUCTOR_ANODE, 0.5 * delta * gap, -0.5 * delta * gap)
    assert tip_contacts.max(initial=0) < n_tips
    return tip_contacts, conductor_tip.astype(np.int64), conductor_id, potential


def lattice_network(n_rods: int, rng: np.random.Generator, p_bond: float = 0.7, free: float = 0.2):
    """Diluted cubic bond lattice between electrodes plus free rods (see module docstring)."""
    n_net = int(round((1 - free) * n_rods))
    side = max(2, int(round((n_net / (3 * p_bond)) ** (1 / 3))))
    idx = np.arange(side**3).reshape(side, side, side)  # (x, y, z)
    bonds = []
    for axis in range(3):
        a = np.take(idx, np.arange(side - 1), axis=axis).ravel()
        b = np.take(idx, np.arange(1, side), axis=axis).ravel()
        bonds.append(np.stack([a, b], axis=1))
    bonds = np.concatenate(bonds)
    bonds = bonds[rng.permutation(bonds.shape[0])[: min(n_net, bonds.shape[0])]]
    flip = rng.random(bonds.shape[0]) < 0.5
    bonds[flip] = bonds[flip, ::-1]
    n_rods = max(n_rods, bonds.shape[0])
    junction_of_tip = np.full(2 * n_rods, -1, dtype=np.int64)
    junction_of_tip[: 2 * bonds.shape[0]] = bonds.ravel()
    z = np.arange(side**3) % side
    return n_rods, *_finish(n_rods, junction_of_tip, z == 0, z == side - 1, side - 1)


def chain_network(n_rods: int, rng: np.random.Generator, free: float = 0.2, length: int = 30):
    """Cross-linked straight chains spanning the gap plus dangling rods and free rods."""
    n_net = int(round((1 - free) * n_rods))
    n_chain = max(1, int(n_net * 0.8) // length)
    # junction (chain c, level h) = c * (length + 1) + h, levels 0..length
    jid = lambda c, h: c * (length + 1) + h  # noqa: E731
    c, h = np.meshgrid(np.arange(n_chain), np.arange(length), indexing="ij")
    chain_bonds = np.stack([jid(c, h), jid(c, h + 1)], axis=-1).reshape(-1, 2)
    # cross links: merge junctions of neighbouring chains at random levels
    n_dangle = n_net - chain_bonds.shape[0]
    anchors = rng.integers(0, n_chain * (length + 1), size=max(n_dangle, 0))
    dangling_tip = n_chain * (length + 1) + np.arange(max(n_dangle, 0))
    bonds = np.concatenate([chain_bonds, np.stack([anchors, dangling_tip], axis=1)])
    flip = rng.random(bonds.shape[0]) < 0.5
    bonds[flip] = bonds[flip, ::-1]
    n_junction = n_chain * (length + 1) + max(n_dangle, 0)
    # cross-link: relabel a random 10 % of chain junctions to the same level of the next chain
    merge = np.arange(n_junction)
    pick = rng.integers(0, n_chain - 1, size=n_chain * length // 10) if n_chain > 1 else []
    lev = rng.integers(1, length, size=len(pick))
    merge[jid(np.asarray(pick) + 1, lev)] = jid(np.asarray(pick), lev)
    bonds = merge[bonds]
    junction_of_tip = np.full(2 * n_rods, -1, dtype=np.int64)
    junction_of_tip[: 2 * bonds.shape[0]] = bonds.ravel()
    level = np.full(n_junction, -1)
    level[: n_chain * (length + 1)] = np.arange(n_chain * (length + 1)) % (length + 1)
    return n_rods, *_finish(n_rods, junction_of_tip, level == 0, level == length, length)


def _best(fn, repeat):
    best, out = np.inf, None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[1000, 10_000, 100_000])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args(argv)
    rng = np.random.default_rng(args.seed)
    m = machine()
    print(
        f"{m['cpu_model']} ({m['widest']}, numba target {m['cpu_name']}), "
        f"python {platform.python_version()}, numpy {np.__version__}, scipy {scipy.__version__}, "
        f"networkx {networkx.__version__}, {os.cpu_count()} CPUs, best of {args.repeat}"
    )
    header = (
        f"{'network':8s} {'rods':>8s} {'contacts':>9s} {'filament':>9s} {'topology ms':>12s} {'peer ms':>8s} "
        f"{'solve ms':>9s} {'cg ms':>7s} {'R_eff':>8s} {'KCL resid':>10s}"
    )
    print(header)
    print("-" * len(header))
    for make in (lattice_network, chain_network):
        for n in args.sizes:
            n_rods, tc, ct, cid, pot = make(n, rng)
            t_topo, topo = _best(lambda: classify_rods(n_rods, tc, ct, cid), args.repeat)
            t_peer, peer = _best(lambda: oracles.classify_rods_scipy_networkx(n_rods, tc, ct, cid), args.repeat)
            assert np.array_equal(peer.role, topo.role) and np.array_equal(peer.structure, topo.structure)
            t_solve, sol = _best(lambda: solve_circuit(2 * n_rods, tc, ct, pot), args.repeat)
            t_cg, sol_cg = _best(lambda: solve_circuit(2 * n_rods, tc, ct, pot, solver="cg"), args.repeat)
            assert abs(sol_cg.total_current - sol.total_current) <= 1e-9 * sol.total_current
            name = make.__name__.split("_")[0]
            print(
                f"{name:8s} {n_rods:8d} {tc.shape[0] + ct.shape[0]:9d} {topo.n_filament:9d} "
                f"{1e3 * t_topo:12.1f} {1e3 * t_peer:8.1f} {1e3 * t_solve:9.1f} {1e3 * t_cg:7.1f} "
                f"{sol.effective_resistance:8.4f} "
                f"{sol.kirchhoff_residual:10.1e}"
            )


if __name__ == "__main__":
    main()
