"""The rod currents' field on the tips: the tree against the direct sums, time and error.

Usage: selfas-graph bench current_tree [--checkpoint CKPT ...] [--rods 6000 24000 100000]
       [--carrying 0.5] [--theta 0.3 0.4 0.5 0.6 0.7] [--precision float64 mixed] [--leaf 64]
       [--group 128] [--order 3] [--threads 2] [--reps 5] [--json OUT]

For each scene it times the field of the rods that carry current on every tip, each tip leaving out
its own rod (term 9 without the charges; term 10 asks the same sums at its quadrature points): the
direct sums of ``kernels/currents.py`` (``rod_current_field``, ``rod_current_field_mixed``) and the
tree of ``kernels/currenttree.py`` (its build and its walk, ``method = "tree"``) at each opening
angle and precision, and each combination of ``--leaf``, ``--group`` and ``--order`` (the terms'
``leaf_size``, ``group_size`` and ``order``). Every time is the minimum wall time of ``--reps`` rounds, the kernels timed in
turns within each round. The error of each is taken per tip against the float64 direct sum, relative
to that tip's field: median and 99th percentile. The ratios divide the direct sum's time of the same
precision, measured in the same run, by the tree's.

Scenes: ``--checkpoint`` files (the rods and currents of a run; the rods that carry current are those
of its last circuit solve), and ``--rods N``: N rods with centres uniform in a cube at the Fig. 2
density (0.19 rods per unit volume, unit length, random axes), a fraction ``--carrying`` of them,
drawn at random, carrying currents uniform in (-3, 3) J0 (a gas: the tree's least favourable case;
a network of filaments is more clustered).

Under ``mpiexec -n P`` every rank times every sum whole, and the tree once more as a run does under
MPI, the ranks sharing the moments of its cells and its walks by runs of groups of points and
gathering them (``model/terms/context.py::shared_current_tree``,
``model/terms/currents.py::tree_field``); each time is the slowest rank's, and a line per opening
angle and precision gives the time of the tree whole on every rank over the shared one's.
"""

import argparse
import json
import time

import numpy as np

from selfas_graph.bench.peer import machine, machine_line
from selfas_graph.bench.profile import load_state, start_threads
from selfas_graph.kernels.currenttree import GROUP_SIZE, LEAF_SIZE, ORDER
from selfas_graph.model.terms.context import shared_current_tree
from selfas_graph.model.terms.currents import tree_field
from selfas_graph.parallel import SERIAL, RowBlocks, world

#: rods per unit volume of the Fig. 2 scene
DENSITY = 0.19
#: the wire radius of the synthetic scenes (the scenes' D = 0.06)
WIRE_RADIUS = 0.03


def gas(n, carrying, seed=1):
    """(position, current, wire radius, name): n unit rods uniform in a cube at :data:`DENSITY`."""
    rng = np.random.default_rng(seed)
    side = (n / DENSITY) ** (1 / 3)
    centre = rng.uniform(0, side, (n, 3))
    axis = rng.normal(size=(n, 3))
    axis /= np.linalg.norm(axis, axis=1)[:, None]
    position = np.empty((2 * n, 3))
    position[0::2], position[1::2] = centre - 0.5 * axis, centre + 0.5 * axis
    current = np.where(rng.random(n) < carrying, rng.uniform(-3, 3, n), 0.0)
    return position, current, WIRE_RADIUS, f"gas of {n} rods, {carrying:g} carrying current"


def from_checkpoint(path):
    sim, origin = load_state(argparse.Namespace(checkpoint=path, extra=[], scenario=None, settle=0))
    return sim.state.position.copy(), sim.network.current.copy(), 0.5 * sim.params.rods.diameter, origin


def measure(position, current, w, thetas, precisions, reps, comm=SERIAL, shapes=None):
    """``(n_points, n_active, rows)``: a row (method, precision, theta, leaf, group, order, ms, median
    and 99th-percentile error) per sum timed; the tree at each opening angle and each of ``shapes``,
    ``(leaf_size, group_size, order)`` triples (None: the defaults). Under MPI (``comm`` of more than
    one rank) every rank times every sum whole, and the tree once more with the ranks sharing its
    moments and walks as a run does (the module docstring); each time is the slowest rank's."""
    from selfas_graph.kernels import currenttree as ct
    from selfas_graph.kernels.currents import rod_current_field, rod_current_field_mixed

    shapes = [(ct.LEAF_SIZE, ct.GROUP_SIZE, ct.ORDER)] if shapes is None else list(shapes)
    active = np.flatnonzero(current != 0.0).astype(np.int64)
    points = np.ascontiguousarray(position)
    exclude = (np.arange(len(points)) // 2).astype(np.int64)
    direct = {"float64": rod_current_field, "mixed": rod_current_field_mixed}
    runs = {}
    for prec in precisions:
        runs[("direct", prec, None, None)] = lambda k=direct[prec], o=np.empty_like(points): (
            k(points, exclude, position, active, current, w, o),
            o,
        )[1]
        for theta in thetas:
            for shape in shapes:

                def tree(theta=theta, shape=shape, mixed=prec == "mixed", o=np.empty_like(points)):
                    leaf, group, order = shape
                    t = ct.build_current_tree(position, active, current, leaf, order)
                    ct.current_tree_field(t, points, exclude, theta, w, o, mixed, group)
                    return o

                runs[("tree", prec, theta, shape)] = tree
        if comm.size > 1:
            blocks = RowBlocks(len(current), comm)
            for theta in thetas:
                for shape in shapes:

                    def shared(theta=theta, shape=shape, mixed=prec == "mixed", o=np.empty_like(points)):
                        leaf, group, order = shape
                        t = shared_current_tree(blocks, position, active, current, leaf, order)
                        tree_field(blocks, t, points, exclude, theta, w, o, mixed, group)
                        return o

                    runs[("tree, shared by the ranks", prec, theta, shape)] = shared
    best = {key: np.inf for key in runs}
    for _ in range(max(reps, 1) + 1):  # the first round also compiles
        for key, run in runs.items():
            comm.Barrier()
            t0 = time.perf_counter()
            run()
            # under MPI the slowest rank's time: the ranks wait for it at the next gather
            best[key] = min(best[key], max(comm.allgather(time.perf_counter() - t0)))
    ref = np.empty_like(points)  # the float64 direct sum, whether timed or not
    rod_current_field(points, exclude, position, active, current, w, ref)
    size = np.linalg.norm(ref, axis=1)
    size[size == 0.0] = 1.0
    rows = []
    for key, run in runs.items():
        err = np.linalg.norm(run() - ref, axis=1) / size
        leaf, group, order = key[3] if key[3] is not None else (None, None, None)
        rows.append(dict(method=key[0], precision=key[1], theta=key[2], leaf=leaf, group=group, order=order,
                         ms=1e3 * best[key], median_error=float(np.median(err)),
                         p99_error=float(np.percentile(err, 99))))  # fmt: skip
    return len(points), len(active), rows


def main(argv=None):
    ap = argparse.ArgumentParser(prog="selfas-graph bench current_tree", description=__doc__.split("\n")[0])
    ap.add_argument("--checkpoint", nargs="*", default=[], help="checkpoint files whose rods and currents to use")
    ap.add_argument("--rods", nargs="*", type=int, default=[], help="sizes of the synthetic gas")
    ap.add_argument("--carrying", type=float, default=0.5, help="fraction of the gas's rods carrying current")
    ap.add_argument("--theta", nargs="+", type=float, default=[0.3, 0.4, 0.5, 0.6, 0.7], help="opening angles")
    ap.add_argument("--precision", nargs="+", choices=("float64", "mixed"), default=["float64", "mixed"])
    ap.add_argument("--leaf", nargs="+", type=int, default=[LEAF_SIZE], help="rods per leaf of the tree")
    ap.add_argument("--group", nargs="+", type=int, default=[GROUP_SIZE], help="points per walk")
    ap.add_argument("--order", nargs="+", type=int, choices=(2, 3), default=[ORDER], help="highest moment")
    ap.add_argument("--threads", type=int, default=None, help="numba threads (default: numba's)")
    ap.add_argument("--reps", type=int, default=5, help="rounds; each time is the minimum")
    ap.add_argument("--json", help="write the rows as JSON")
    args = ap.parse_args(argv)
    if not args.checkpoint and not args.rods:
        ap.error("name a scene: --checkpoint FILE ... or --rods N ...")
    if any(not 0.0 <= t < 1.0 for t in args.theta):
        ap.error("--theta: opening angles lie in [0, 1)")
    if not 0.0 < args.carrying <= 1.0:
        ap.error("--carrying: a fraction in (0, 1]")
    if any(n < 1 for n in args.rods):
        ap.error("--rods: at least one rod")
    if min(args.leaf + args.group) < 1:
        ap.error("--leaf, --group: at least 1")
    shapes = [(leaf, group, order) for leaf in args.leaf for group in args.group for order in args.order]
    if args.threads is not None:
        start_threads(args.threads)
    import numba

    lead = world.rank == 0  # under mpiexec rank 0 prints and writes

    def say(*a):
        if lead:
            print(*a)

    say(machine_line())
    say(f"numba threads: {numba.get_num_threads()}" + (f" x {world.size} MPI ranks" if world.size > 1 else ""))
    scenes = [lambda p=p: from_checkpoint(p) for p in args.checkpoint]
    scenes += [lambda n=n: gas(n, args.carrying) for n in args.rods]
    results = []
    for make in scenes:
        position, current, w, name = make()
        if not np.any(current != 0.0):
            say(f"\n{name}: no rod carries current, nothing to time")
            continue
        n_tips, n_active, rows = measure(position, current, w, args.theta, args.precision, args.reps, world, shapes)
        say(f"\n{name}: {n_tips} tips, {n_active} rods carrying current\n")
        say("| method | precision | opening angle | leaf / group / order | ms | direct / this (same precision) "
            "| median error | 99th pct |")  # fmt: skip
        say("|---|---|---|---|---|---|---|---|")
        direct_ms = {r["precision"]: r["ms"] for r in rows if r["method"] == "direct"}
        for r in rows:
            theta = "" if r["theta"] is None else f"{r['theta']:g}"
            ratio = direct_ms[r["precision"]] / r["ms"]
            shape = "" if r["leaf"] is None else f"{r['leaf']} / {r['group']} / {r['order']}"
            say(f"| {r['method']} | {r['precision']} | {theta} | {shape} | {r['ms']:.2f} | {ratio:.2f} | "
                f"{r['median_error']:.1e} | {r['p99_error']:.1e} |")  # fmt: skip

        def shape_of(r):
            return (r["precision"], r["theta"], r["leaf"], r["group"], r["order"])

        whole = {shape_of(r): r["ms"] for r in rows if r["method"] == "tree"}
        for r in rows:
            if r["method"] == "tree, shared by the ranks":
                key = shape_of(r)
                say(f"{world.size} ranks sharing the tree, {key[0]}, opening angle {key[1]:g}, leaf / group / "
                    f"order {key[2]} / {key[3]} / {key[4]}: "
                    f"{whole[key] / r['ms']:.2f} times faster than the whole tree on every rank")  # fmt: skip
        results.append(dict(scene=name, tips=n_tips, carrying=n_active, rows=rows))
    if args.json and lead:
        with open(args.json, "w") as f:
            out = dict(machine=machine(), threads=numba.get_num_threads(), ranks=world.size, scenes=results)
            json.dump(out, f, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
