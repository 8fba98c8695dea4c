"""The reduced nodal system of a resistor network: assembly, sparse solve, and the memo of the
last system solved (docs/model.md 'Circuit'). Used by :mod:`.circuit`."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import cg, splu

from selfas_graph.kernels.graph import component_labels

#: relative residual at which the "cg" solver stops. On a 10^5-rod diluted cubic
#: lattice (37 000 unknowns) it reaches it in 354 Jacobi-CG iterations and then
#: differs from the direct solution by 8e-13 (potentials of order 16): round-off.
CG_RTOL = 1e-14


def _solve_direct(A: sp.csc_matrix, b: np.ndarray) -> np.ndarray:
    """Sparse LU of the SPD reduced Laplacian.

    A is symmetric positive definite (an irreducibly diagonally dominant
    M-matrix per block), so pivoting on the diagonal is safe and a symmetric
    fill-reducing ordering keeps the factors sparse. Measured on a 10^5-rod
    diluted cubic lattice (37 000 unknowns): this takes 0.8-0.9 s and 9e6 factor
    entries; ``spsolve``'s default (COLAMD with partial pivoting) took 111 s.
    """
    lu = splu(A, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True})
    return lu.solve(b)


#: "auto" uses the direct solver below this many unknowns and "cg" above. Measured with
#: selfas_graph/bench/circuit.py (docs/performance.md 'Contacts, events, topology and circuit'): a
#: diluted cubic lattice favours CG from 10^4 rods (1.03 s direct / 0.21 s CG at 10^5, Intel Xeon),
#: cross-linked chains the direct solver at every size (0.08 s / 0.27 s at 10^5); no one size suits both,
#: and at 10^5 rods this one takes the slower solver for both (the lattice has 37 000 unknowns, the chains
#: 72 000). Below 10^4 unknowns, the scenes' sizes, both take milliseconds.
AUTO_CG_UNKNOWNS = 50_000


class SolveMemo:
    """The last reduced system solved and its solution, for one caller (a :class:`~.network.Network`).

    A system equal, byte for byte, to the last one solved (matrix in compressed columns,
    right-hand side, solver) returns a copy of the last solution: the solvers are
    deterministic, so that is the solution a new solve would give, bit for bit. In the
    Fig. 2 run after the short circuit about half of the solves meet an unchanged system
    (the contact events fell in structures without current), and the factorisation is
    about half of a solve (docs/performance.md, "Topology and circuit per event").
    A memo only saves time: a solve without one gives the same bits.
    """

    def __init__(self):
        self.key: tuple | None = None
        self.solution: np.ndarray | None = None
        #: number of systems solved afresh and answered from the memo
        self.solved = 0
        self.reused = 0

    def clear(self) -> None:
        self.key = self.solution = None

    def solve(self, A: sp.csc_matrix, b: np.ndarray, solver: str) -> np.ndarray:
        key = (solver, A.shape, A.indptr.tobytes(), A.indices.tobytes(), A.data.tobytes(), b.tobytes())
        if self.key is not None and self.key == key:
            self.reused += 1
            return self.solution.copy()
        x = _solve_spd_new(A, b, solver)
        self.key, self.solution = key, x.copy()
        self.solved += 1
        return x


def _solve_spd(A: sp.csc_matrix, b: np.ndarray, solver: str, memo: SolveMemo | None = None) -> np.ndarray:
    """Solve the reduced system with ``solver`` ("direct", "cg" or "auto", see :func:`solve_circuit`),
    through ``memo`` when one is given (:class:`SolveMemo`)."""
    if memo is not None:
        return memo.solve(A, b, solver)
    return _solve_spd_new(A, b, solver)


def _solve_spd_new(A: sp.csc_matrix, b: np.ndarray, solver: str) -> np.ndarray:
    if solver == "auto":
        solver = "cg" if A.shape[0] > AUTO_CG_UNKNOWNS else "direct"
    if solver == "cg":
        jacobi = sp.diags(1.0 / A.diagonal())
        # iterations grow like sqrt(condition number) ~ the network's diameter in
        # rods (354 on the 10^5-rod lattice); long thin networks need more and are
        # cheap for the direct solver, so the cap hands them over early
        maxiter = min(2 * A.shape[0], 2000) + 10
        x, info = cg(A, b, rtol=CG_RTOL, atol=0.0, M=jacobi, maxiter=maxiter)
        if info == 0:
            return x
    return _solve_direct(A, b)


def _potentials(n_nodes, u, v, g, is_dir, psi_dir, solver, memo=None) -> tuple:
    """Node potentials of a resistor network with Dirichlet nodes (NaN where floating), as ``(psi, comp,
    comp_active)``: the potentials, each node's connected component and which components were solved.

    ``u``, ``v`` are the resistors' end nodes (``u != v``), ``g`` their conductances.
    Only the connected components with two different Dirichlet values are solved;
    a component with one value sits at it exactly, one with none floats (NaN).
    """
    n_comp, comp = component_labels(
        n_nodes, np.ascontiguousarray(u, dtype=np.int64), np.ascontiguousarray(v, dtype=np.int64)
    )
    dir_nodes = np.flatnonzero(is_dir)
    comp_lo = np.full(n_comp, np.inf)
    comp_hi = np.full(n_comp, -np.inf)
    np.minimum.at(comp_lo, comp[dir_nodes], psi_dir[dir_nodes])
    np.maximum.at(comp_hi, comp[dir_nodes], psi_dir[dir_nodes])
    comp_has_dir = np.isfinite(comp_lo)
    comp_active = comp_has_dir & (comp_hi > comp_lo)

    psi = np.full(n_nodes, np.nan)
    # components with a single Dirichlet value sit at it exactly: no solve, no round-off
    const_node = comp_has_dir[comp] & ~comp_active[comp]
    psi[const_node] = comp_lo[comp[const_node]]
    psi[dir_nodes] = psi_dir[dir_nodes]

    interior = comp_active[comp] & ~is_dir
    n_int = int(interior.sum())
    if n_int:
        # reduced Laplacian assembled directly from the edge list:
        # diagonal = summed conductance at the node (all resistors, including those
        # to Dirichlet nodes); off-diagonal -g per interior-interior resistor
        # (duplicates summed); resistors to a Dirichlet node move g psi_D to the
        # right-hand side. With unit conductances every sum is an exact integer.
        index = np.full(n_nodes, -1, dtype=np.int64)
        index[interior] = np.arange(n_int)
        iu, iv = index[u], index[v]
        degree = np.bincount(u, weights=g, minlength=n_nodes) + np.bincount(v, weights=g, minlength=n_nodes)
        both = (iu >= 0) & (iv >= 0)
        rows = np.concatenate([np.arange(n_int), iu[both], iv[both]])
        cols = np.concatenate([np.arange(n_int), iv[both], iu[both]])
        vals = np.concatenate([degree[interior], -g[both], -g[both]])
        A = sp.coo_matrix((vals, (rows, cols)), shape=(n_int, n_int)).tocsc()
        u_to_d = (iu >= 0) & is_dir[v]
        v_to_d = (iv >= 0) & is_dir[u]
        b = np.bincount(iu[u_to_d], weights=g[u_to_d] * psi_dir[v[u_to_d]], minlength=n_int) + np.bincount(
            iv[v_to_d], weights=g[v_to_d] * psi_dir[u[v_to_d]], minlength=n_int
        )
        psi[interior] = _solve_spd(A, b, solver, memo)
    return psi, comp, comp_active
