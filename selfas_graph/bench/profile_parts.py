"""The parts of a step that ``selfas-graph bench profile`` sorts cProfile's functions into, each a test
on ``"path:function"`` (:func:`part_of`): the force kernels, the neighbour lists, the contact search,
the graph and circuit, the Python layers (docs/performance.md 'One full step of the Fig. 2 scene')."""

import os

#: (part, test on "path:function") in order; the first match wins
PARTS = [
    (
        "tip-tip far sum (direct or tree, slow)",
        lambda f: f.endswith(("tips.py:tip_tip_direct", "tips.py:tip_tip_direct_mixed")) or "kernels/tree" in f,
    ),
    ("tip-tip close pairs (fast, every step)", lambda f: f.endswith("tips.py:tip_tip_fast")),
    (
        "Yukawa sum (slow)",
        lambda f: f.endswith(
            (
                "yukawa.py:yukawa_centres",
                "yukawa.py:yukawa_centres_sorted",
                "yukawa.py:yukawa_centres_sorted_mixed",
                "yukawa.py:yukawa_energy",
            )
        ),
    ),
    (
        # the Morton keys and their sort (kernels/treebuild.py) count with the tip tree above
        "tree of the rod currents (terms 9 and 10, method tree, slow)",
        lambda f: "kernels/currenttree.py" in f,
    ),
    (
        "current field on tips (term 9, slow)",
        lambda f: f.endswith(("currents.py:current_force_on_tips", "currents.py:current_force_on_tips_mixed")),
    ),
    (
        "current field at Lorentz points (term 10, slow)",
        lambda f: "kernels/currents.py" in f or "kernels/lorentz.py" in f,
    ),
    (
        "split brake (close pairs, exact brake)",
        lambda f: f.endswith(
            (
                # the close-pair kernels of kernels/contacts.py serve the brake from Python only from
                # PARALLEL_ROWS tips on; below, the contact search's numpy path calls them (next part)
                "brakes.py:brake_pairs_exact",
                "brakes.py:brake_close_pairs",
                "brakes.py:brake_close_pairs_exact",
                "fields.py:electrode_brake_exact",
            )
        ),
    ),
    ("neighbour-list builds", lambda f: "kernels/cells.py" in f),
    ("fast steps in one compiled call (kernels)", lambda f: "steps.py:fast_steps" in f),
    (
        "contact search and events",
        lambda f: any(p in f for p in ("model/contacts.py", "model/events.py", "kernels/contacts.py")),
    ),
    (
        "graph and circuit on events",
        lambda f: (
            any(
                f"model/{m}.py" in f
                for m in ("graph", "circuit", "network", "topology", "linear", "validate", "contactset")
            )
            or "kernels/graph.py" in f
            or "scipy/sparse/" in f
            or "_superlu" in f  # the circuit's sparse LU: its factorisation (named by module) ...
            or "'SuperLU'" in f
        ),  # ... and its solve, a method of the factors' type
    ),
    (
        "cheap O(n) kernels (walls, fields, integration, bonds)",
        lambda f: "selfas_graph/kernels/" in f and not f.endswith("_jit.py:__call__"),
    ),
    ("force field bookkeeping (Python)", lambda f: "model/terms/" in f),
    ("neighbour-list checks (Python)", lambda f: "model/neighbours.py" in f),
    (
        "integrator and run loop (Python)",
        lambda f: any(
            f"model/{m}.py" in f
            for m in ("integrator", "simulation", "operations", "health", "observables", "compiled")
        ),
    ),
    ("numpy and other", lambda f: True),
]


def part_of(key):
    """The part of cProfile's key ``(path, line, function)``: the first of :data:`PARTS` whose test holds."""
    path, _, fn = key
    name = f"{path.replace(os.sep, '/')}:{fn}"
    for part, test in PARTS:
        if test(name):
            return part
    return PARTS[-1][0]
