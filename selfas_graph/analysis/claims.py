"""The measures of the paper's claims for one saved frame of a run file (docs/model.md "Measures of the paper's claims").

:func:`frame_claims` reads one frame (tip positions, tip charges, tip-tip contacts and rod
currents) from an open :class:`selfas_graph.io.h5md.RunFile` and returns plain floats, NaN
where a measure is undefined (no contact data, too few rods, too narrow a fit range).
:func:`claims_series` does the same for many frames. The measures themselves are the
array functions of :mod:`.moments`, :mod:`.fractal` and :mod:`.skeleton`.

Structures are rods joined by tip-tip contacts (the conductors join none), as in the
``topology`` command; "the largest structure" is the one with the most rods.
"""

from __future__ import annotations

import numpy as np

from .fractal import mass_radius_dimension, radius_of_gyration, rg_dimension
from .moments import current_moment, junction_charge, monopole_moment, unpaired_charge
from .skeleton import contact_nodes, cycle_rank, junction_degrees, loop_lengths, structures

__all__ = ["CLAIM_KEYS", "claims_of_arrays", "claims_series", "frame_claims"]

NAN = float("nan")

#: the keys of :func:`frame_claims`, in the order the CLI prints them, with their meaning
CLAIM_KEYS = {
    "time": "simulated time of the frame (t0)",
    "step": "time step of the frame",
    "structures": "structures of 2 or more rods joined by tip contacts (topology also counts a lone rod on a conductor)",
    "largest_structure_rods": "rods in the largest structure",
    "largest_moment_q": "|m_q| of the largest structure, m_q = sum q_k x_k (Z_M0 e L)",
    "largest_moment_q_z": "m_q,z of the largest structure (Z_M0 e L)",
    "largest_moment_ratio": "|m_q| of the largest structure over mean |q| L, the mean moment of a rod of length L",
    "largest_moment_J_z": "m_J,z of the largest structure about the z axis, m_J = 1/2 sum J x_a x x_b (J0 L^2)",
    "moment_J_z": "m_J,z of all rod currents about the z axis (J0 L^2)",
    "unpaired_charge_largest": "sum |q| at the free tips (no tip contact) of the largest structure (Z_M0 e)",
    "junction_charge_largest": "sum |sum q| over the contact clusters of the largest structure (Z_M0 e)",
    "fractal_dimension": "mass-radius dimension of the largest structure about centres on it "
    "(>= 30 rods; NaN, not testable, while its R_g < 4 L)",
    "fractal_dimension_err": "its uncertainty sqrt(se^2 + d^2)",
    "fractal_dimension_se": "standard error of the fitted slope",
    "fractal_r_min": "fit range of the mass-radius dimension: smallest r (L)",
    "fractal_r_max": "largest r (L)",
    "rg_dimension": "D from R_g ~ N^(1/D) over the structures of the frame with R_g >= 1 L "
    "(NaN, not testable, with fewer than 3 distinct sizes or while their R_g spans less than a factor 4)",
    "rg_dimension_err": "its uncertainty",
    "rg_dimension_se": "standard error of the fitted slope, carried to D",
    "rg_n_min": "fit range of the R_g dimension, in rods: smallest structure",
    "rg_n_max": "largest structure (rods)",
    "cycle_rank": "independent loops E - V + C of the contact graph",
    "cycle_rank_largest": "independent loops of the largest structure",
    "loop_length_median": "median length (rods) of the loops of a cycle basis",
    "loop_length_max": "longest loop of that basis (rods)",
    "junctions": "contact clusters (two or more tips in contact)",
    "junction_degree_mean": "mean tips per contact cluster",
    "junction_degree_max": "most tips in one contact cluster",
}


def _fit(prefix, fit, lo, hi, out):
    out[prefix] = fit.value
    out[prefix + "_err"] = fit.err
    out[prefix + "_se"] = fit.se
    out[lo], out[hi] = fit.fit_range


def claims_of_arrays(position, tip_charge, tip_contacts, current=None, loops=True) -> dict:
    """Every measure of :data:`CLAIM_KEYS` but time and step, from one frame's arrays.

    Parameters
    ----------
    position : (n_tips, 3) float64
    tip_charge : (n_tips,) float64
    tip_contacts : (m, 2) int
        Tip pairs in contact.
    current : (n_rods,) float64, optional
        Rod currents (J0); None gives NaN current moments.
    loops : bool
        Compute the loop lengths (a cycle basis; the slowest measure).
    """
    position = np.asarray(position, dtype=np.float64).reshape(-1, 3)
    tip_charge = np.asarray(tip_charge, dtype=np.float64).reshape(-1)
    tip_contacts = np.asarray(tip_contacts, dtype=np.int64).reshape(-1, 2)
    n_rods = position.shape[0] // 2
    label, size = structures(n_rods, tip_contacts)
    n_s = size.shape[0]
    out = {"structures": float(n_s)}
    big = int(np.argmax(size)) if n_s else -1
    rods = np.flatnonzero(label == big) if n_s else np.zeros(0, dtype=np.int64)
    out["largest_structure_rods"] = float(size[big]) if n_s else 0.0
    mean_rod = float(np.abs(tip_charge[0::2]).mean()) if n_rods else NAN
    if n_s:
        m_q = monopole_moment(position, tip_charge, label, n_s)[big]
        out["largest_moment_q"] = float(np.linalg.norm(m_q))
        out["largest_moment_q_z"] = float(m_q[2])
        out["largest_moment_ratio"] = out["largest_moment_q"] / mean_rod if mean_rod > 0 else NAN
        out["unpaired_charge_largest"] = float(unpaired_charge(tip_charge, tip_contacts, label, n_s)[big])
        _, node = contact_nodes(n_rods, tip_contacts)
        out["junction_charge_largest"] = float(junction_charge(tip_charge, node, label, n_s)[big])
    else:
        for key in (
            "largest_moment_q",
            "largest_moment_q_z",
            "largest_moment_ratio",
            "unpaired_charge_largest",
            "junction_charge_largest",
        ):
            out[key] = NAN
    if current is not None and n_s:
        out["largest_moment_J_z"] = float(current_moment(position, current, label, n_s)[big, 2])
        out["moment_J_z"] = float(current_moment(position, current, np.zeros(n_rods, dtype=np.int64), 1)[0, 2])
    else:
        out["largest_moment_J_z"] = NAN
        out["moment_J_z"] = (
            float(current_moment(position, current, np.zeros(n_rods, dtype=np.int64), 1)[0, 2])
            if current is not None and n_rods
            else NAN
        )
    _fit("fractal_dimension", mass_radius_dimension(position, rods), "fractal_r_min", "fractal_r_max", out)
    rg, rg_size = radius_of_gyration(position, label, n_s)
    _fit("rg_dimension", rg_dimension(rg_size, rg), "rg_n_min", "rg_n_max", out)
    total, per = cycle_rank(n_rods, tip_contacts, label, n_s)
    out["cycle_rank"] = float(total)
    out["cycle_rank_largest"] = float(per[big]) if n_s else 0.0
    ll = loop_lengths(n_rods, tip_contacts) if loops else None
    out["loop_length_median"] = float(np.median(ll)) if ll is not None and len(ll) else NAN
    out["loop_length_max"] = float(ll.max()) if ll is not None and len(ll) else NAN
    deg = junction_degrees(n_rods, tip_contacts)
    out["junctions"] = float(len(deg))
    out["junction_degree_mean"] = float(deg.mean()) if len(deg) else NAN
    out["junction_degree_max"] = float(deg.max()) if len(deg) else NAN
    return out


def _graph_of_frame(run, k):
    """The graph record saved with position frame ``k`` (the same step), or None: the rule of a saved
    frame (:attr:`selfas_graph.io.frame.SavedFrame.graph`)."""
    return run.frame(k).graph


def frame_claims(run, frame=None, loops=True, t=None) -> dict[str, float]:
    """The claim measures of one frame of a run file, as floats (NaN where undefined).

    Parameters
    ----------
    run : selfas_graph.io.h5md.RunFile
        An open run file.
    frame : int, optional
        Frame index; negative counts from the end (default: the last frame).
    loops : bool
        Compute the loop lengths too.
    t : float, optional
        The frame nearest this simulated time instead of ``frame`` (as ``analyze --time``).

    Returns
    -------
    dict with the keys of :data:`CLAIM_KEYS`. A frame without contact data (a run with
    contacts off) has only time, step and NaN for every other key.
    """
    if not hasattr(run, "frame_index"):
        raise TypeError(f"frame_claims(run, ...): an open RunFile (with RunFile(path) as run: ...), got {run!r}")
    k = run.frame_index(frame, t=t)  # frame and t both given: refused, as RunFile.position does
    out = {"time": float(run.time[k]), "step": float(run.step[k])}
    g = _graph_of_frame(run, k)
    if g is None:
        return out | {key: NAN for key in CLAIM_KEYS if key not in out}
    current = np.asarray(g["current"], dtype=np.float64)
    return out | claims_of_arrays(run.position(k), run.tip_charge, g["tip_contacts"], current, loops=loops)


def claims_series(run, frames=None, loops=True) -> dict[str, np.ndarray]:
    """:func:`frame_claims` of several frames (default all; a sequence of frame indices, or a ``slice``
    of the run's frames) as arrays, one entry per frame."""
    if frames is None:
        frames = range(run.n_frames)
    elif isinstance(frames, slice):
        frames = range(run.n_frames)[frames]
    rows = [frame_claims(run, k, loops=loops) for k in frames]
    return {key: np.array([r.get(key, NAN) for r in rows], dtype=np.float64) for key in CLAIM_KEYS}
