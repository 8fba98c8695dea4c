"""Magnetic moments of structures: the paper's "bigger magnetic dipole" (docs/model.md "Measures of the paper's claims").

Arrays in, arrays out. Layout as everywhere (docs/model.md 'Rods'): rod ``i`` has tip a at
row ``2 i`` (magnetic charge ``+q_i``) and tip b at row ``2 i + 1`` (``-q_i``); its current
``J_i`` is positive from tip a to tip b. A structure is a set of rods given by a label per rod
(``structure[i]`` in ``0 .. n_structures - 1``, ``-1`` for a rod in no structure), as
:func:`selfas_graph.analysis.skeleton.structures` or
:func:`selfas_graph.model.graph.classify_rods` make them.

Units (docs/model.md 'Reduced units'): moments in Z_M0 e L; a rod of charge q has |m| = q.

* :func:`monopole_moment` -- ``m_q = sum_k q_k x_k`` over the tips of each structure. The
  tips of a structure carry no net charge, so ``m_q`` does not depend on the origin; a
  head-to-tail chain of N equal rods has ``|m_q| = N q``, a head-to-head pair 0.
* :func:`current_moment` -- ``m_J = (1/2) sum_i J_i (x_a,i - o) x (x_b,i - o)`` about a point
  ``o`` of the scene axis (J in J0; the Gaussian 1/c is absorbed by J0). A closed loop
  carrying J has ``m_J = J A n`` (A the area it encloses); an open path's ``m_J,z`` depends
  on the axis through ``o``, not on where along it ``o`` sits.
* :func:`unpaired_charge` -- the monopole charge at the free tips of each structure (tips in
  no tip-tip contact; a tip touching only an electrode is free, since no other monopole
  pairs it), as ``sum |q_k|`` over those tips.
* :func:`junction_charge` -- ``sum |sum q|`` over the contact clusters of each structure: the
  charge left unpaired inside junctions (0 for head-to-tail contacts of equal rods).
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "current_moment",
    "junction_charge",
    "monopole_moment",
    "rod_moment",
    "unpaired_charge",
]


def _labels(structure, n_rods):
    structure = np.asarray(structure, dtype=np.int64).reshape(-1)
    if structure.shape[0] != n_rods:
        raise ValueError(f"structure has {structure.shape[0]} labels for {n_rods} rods: one label per rod")
    return structure


def _n_structures(structure, n_structures):
    return int(structure.max(initial=-1)) + 1 if n_structures is None else int(n_structures)


def _sum_by(label, values, n):
    """Sum rows of ``values`` into ``n`` bins by ``label``; rows with label -1 are dropped."""
    keep = label >= 0
    values = np.asarray(values, dtype=np.float64)
    out = np.zeros((n,) + values.shape[1:])
    np.add.at(out, label[keep], values[keep])
    return out


def rod_moment(position, tip_charge):
    """Monopole moment of each rod on its own, ``q_i (x_a - x_b)`` (n_rods, 3); ``|m| = q_i`` for unit rods."""
    position = np.asarray(position, dtype=np.float64).reshape(-1, 3)
    q = np.asarray(tip_charge, dtype=np.float64).reshape(-1)
    return q[0::2, None] * position[0::2] + q[1::2, None] * position[1::2]


def monopole_moment(position, tip_charge, structure, n_structures=None):
    """``m_q = sum_k q_k x_k`` over the tips of each structure.

    Parameters
    ----------
    position : (n_tips, 3) float64
    tip_charge : (n_tips,) float64
    structure : (n_rods,) int
        Structure of each rod, -1 for none.
    n_structures : int, optional
        Number of structures (default: the largest label + 1).

    Returns
    -------
    (n_structures, 3) float64, units Z_M0 e L.
    """
    m = rod_moment(position, tip_charge)
    structure = _labels(structure, m.shape[0])
    return _sum_by(structure, m, _n_structures(structure, n_structures))


def current_moment(position, current, structure, n_structures=None, origin=(0.0, 0.0, 0.0)):
    """``m_J = (1/2) sum_i J_i (x_a,i - o) x (x_b,i - o)`` over the rods of each structure.

    Parameters
    ----------
    position : (n_tips, 3) float64
    current : (n_rods,) float64
        Rod currents, positive from tip a to tip b (units J0).
    structure : (n_rods,) int
    n_structures : int, optional
    origin : (3,) float
        A point ``o`` of the scene axis (default the origin, on the z axis).

    Returns
    -------
    (n_structures, 3) float64, units J0 L^2 (= Z_M0 e L with the Gaussian 1/c in J0).
    """
    position = np.asarray(position, dtype=np.float64).reshape(-1, 3) - np.asarray(origin, dtype=np.float64)
    current = np.asarray(current, dtype=np.float64).reshape(-1)
    structure = _labels(structure, current.shape[0])
    m = 0.5 * current[:, None] * np.cross(position[0::2], position[1::2])
    return _sum_by(structure, m, _n_structures(structure, n_structures))


def unpaired_charge(tip_charge, tip_contacts, structure, n_structures=None):
    """``sum |q_k|`` over the free tips (in no tip-tip contact) of each structure, (n_structures,)."""
    q = np.asarray(tip_charge, dtype=np.float64).reshape(-1)
    structure = _labels(structure, q.shape[0] // 2)
    touched = np.zeros(q.shape[0], dtype=bool)
    touched[np.asarray(tip_contacts, dtype=np.int64).reshape(-1)] = True
    free = np.where(touched, 0.0, np.abs(q))
    return _sum_by(structure, free[0::2] + free[1::2], _n_structures(structure, n_structures))


def junction_charge(tip_charge, node_of_tip, structure, n_structures=None):
    """``sum |sum q|`` over the contact clusters (merged nodes of two or more tips) of each structure.

    ``node_of_tip`` is the merged node of each tip (:func:`selfas_graph.model.circuit.merge_tips`).
    """
    q = np.asarray(tip_charge, dtype=np.float64).reshape(-1)
    node = np.asarray(node_of_tip, dtype=np.int64).reshape(-1)
    structure = _labels(structure, q.shape[0] // 2)
    n_nodes = int(node.max(initial=-1)) + 1
    tips_per_node = np.bincount(node, minlength=n_nodes)
    node_q = np.bincount(node, weights=q, minlength=n_nodes)
    node_structure = np.full(n_nodes, -1, dtype=np.int64)
    node_structure[node] = np.repeat(structure, 2)
    junction = tips_per_node >= 2
    return _sum_by(np.where(junction, node_structure, -1), np.abs(node_q), _n_structures(structure, n_structures))
