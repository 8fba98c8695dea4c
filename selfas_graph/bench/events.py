"""Cost of contact detection and events, and of a topology update plus circuit solve.

Usage::

    selfas-graph bench events [--scenario scenarios/fig2.toml] [--settle 2000] [--steps 300]
                                 [--sizes 1000 10000 100000] [--batch 10 1000] [--repeat 3]
                                 [--checkpoint RUN.checkpoint.h5] [--run-steps 1000]
                                 [--skip-a] [--skip-b] [--skip-c]

(a) Per-step overhead of contact detection and events when no event happens, on the
    Fig. 2 scene (1200 rods, all its terms). The scene first runs ``--settle`` steps
    so that contacts exist, then, from that same state, three measurements:

    * ``in the run``: the wall time of the contact update of each step (tip
      neighbour list check + close-pair count + release check + electrode planes,
      and on steps with events the graph update and circuit solve), recorded while
      the full scene runs; the median over steps without an event is the number
      to compare with the 5 % goal;
    * ``tracker alone``: ``ContactTracker.search`` repeated on the settled positions,
      where nothing changes; and its path for a step with news both ways on them, the kernel
      pass (``search_news``) and the numpy passes (``search_numpy``);
    * ``frozen A/B``: velocities set to zero, every force off except a weak ambient
      brake (and the electrode walls, which define the planes) and dt = 1e-9, so nothing
      moves and no event happens; steps with ``contacts.enabled``
      true minus false, against a full Fig. 2 step;
    * ``Fig. 2 A/B``: the full scene with contacts on minus off, stepped alternately
      (the tip list then also grows from r* to 1.5 r* for the brake; events happen).

    Percentages are of the median full step without an event.

    The goal is an overhead under 5 % of a full step.

(b) ``ConnectivityGraph`` on networks of 10^3, 10^4, 10^5 rods (cross-linked chains
    spanning two electrodes, dangling rods and 20 % free rods: the ``chains`` network
    of ``selfas_graph/bench/circuit.py``): the graph holds the network minus a batch of tip
    contacts; timed are ``apply`` of that batch as TIP_CONTACT events (graph mutation
    plus the topology it needs to detect a short circuit), ``topology()`` (cached by
    then), and ``solve()``. Fresh ``classify_rods`` time is shown for reference.
    Best of ``--repeat``; the batch is released (untimed) between repeats.

(c) Topology and circuit per event in the run: from the Fig. 2 scene after ``--settle``
    steps, or from a checkpoint (``--checkpoint RUN.checkpoint.h5``, read only; e.g. a
    late state of a Fig. 2 run, after the short circuit), ``--run-steps`` steps are run
    with the network's work on each step with events timed (thread CPU time, which the other
    processes on a shared machine disturb little): ``Network.update`` as a whole, and within it
    the new contact set (``ContactSet.apply``), ``classify_rods`` with its parts (tip merge,
    components, filament search, the rest being input checks and numpy glue) and the circuit
    (``Network.solve``): calls per 1000 steps, median cost per call, and their share of the CPU
    time of the steps. The graphs of the first
    ``--peer-graphs`` calls are kept and classified again by the scipy/networkx
    implementation the kernels replaced (``selfas_graph/bench/oracles.py``), the peer of the ratio,
    and the two results are checked to be the same.

Prints markdown tables.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import platform
import time
from pathlib import Path

import numba
import numpy as np

from selfas_graph import Simulation, load_scenario
from selfas_graph.io.checkpoint import read_checkpoint
from selfas_graph.io.scenario import scenario_from_text
from selfas_graph.model import contactset as contactset_module
from selfas_graph.model import events as ev
from selfas_graph.model import topology as topology_module
from selfas_graph.model.contactset import ContactSet
from selfas_graph.model.graph import ConnectivityGraph
from selfas_graph.model.network import Network
from selfas_graph.model.params import AmbientBrake, ForceParams

from . import oracles
from .circuit import chain_network
from .peer import machine

ROOT = Path(__file__).resolve().parents[2]
#: set (unless set) by the command line, not on import (tests import this): a running job's file
#: is read only here (``selfas-graph bench`` sets them too)
COMMAND_ENV = {"HDF5_USE_FILE_LOCKING": "FALSE"}


# --------------------------------------------------------------------------- (a)
def _with(params, contacts=None, forces=None):
    """A copy of frozen parameters with the contact switch and/or the force terms replaced. Without
    contacts the circuit can never close, and the scene refuses it and the rod-current terms: they go
    too (they cost nothing before a short circuit)."""
    changes = {} if forces is None else {"forces": forces}
    if contacts is not None:
        changes["contacts"] = dataclasses.replace(params.contacts, enabled=contacts)
        if not contacts:
            f = changes.get("forces", params.forces)
            changes.update(circuit=None, forces=dataclasses.replace(f, current_field=None, current_lorentz=None))
    return dataclasses.replace(params, **changes)


def _interleaved(sims, steps, warmup=5):
    """Per-step wall times (s) of several simulations stepped in turn, (steps, len(sims)).

    Stepping them alternately exposes them to the same machine load (the medians of
    separate runs drift by ~0.1 ms on a shared 2-core machine).
    """
    for sim in sims:
        sim.step(warmup)
    times = np.empty((steps, len(sims)))
    for i in range(steps):
        for j, sim in enumerate(sims):
            t0 = time.perf_counter()
            sim.step()
            times[i, j] = time.perf_counter() - t0
    return times


def _record_contact_updates(sim):
    """Wrap ``sim.update_network`` to record (seconds, events produced) of every call."""
    record = []
    inner = sim.update_network

    def timed():
        n = len(sim.events)
        t0 = time.perf_counter()
        inner()
        record.append((time.perf_counter() - t0, len(sim.events) - n))

    sim.update_network = timed
    return record


def contact_overhead(scenario_path, settle, steps):
    sc = load_scenario(scenario_path)
    params = sc.params
    sim = Simulation(params)
    t0 = time.perf_counter()
    sim.step(settle)
    settle_s = time.perf_counter() - t0
    settled = sim.state.copy()
    n_contacts = sim.contacts.n_contacts

    # full Fig. 2 steps, contacts on and off, from the same state, interleaved
    on = Simulation(params, state=settled.copy())
    off = Simulation(_with(params, contacts=False), state=settled.copy())
    on.step(5)
    record = _record_contact_updates(on)
    full = _interleaved([on, off], steps, warmup=0)
    rec = np.array(record)
    quiet = rec[:, 1] == 0
    step_on, step_off = np.median(full, axis=0)
    step_on_quiet = float(np.median(full[quiet, 0]))
    upd_quiet = float(np.median(rec[quiet, 0]))
    upd_event = float(np.median(rec[~quiet, 0])) if (~quiet).any() else float("nan")
    n_event_steps = int((~quiet).sum())
    n_events = int(rec[:, 1].sum())
    mean_upd = float(rec[:, 0].mean())

    # the tracker alone on the settled positions: after the first call nothing changes
    st = on.state
    ff, tracker = on.force_field, on.network.tracker
    on.network.update(st.position, ff.tip_neighbours(st.position), st.step, st.time)
    contacts = on.network.contacts
    reps = max(200, 5 * steps)
    times = np.empty(reps)
    for i in range(reps):
        t0 = time.perf_counter()
        rows = tracker.search(contacts, st.position, ff.tip_neighbours(st.position), st.step, st.time)
        times[i] = time.perf_counter() - t0
        assert not rows, "the tracker found an event on unchanged positions"
    tracker_alone = float(np.median(times))
    # a step with news, both ways on the same positions: the kernel pass and the numpy passes it replaced
    news = {}
    for name, path in (("kernel", tracker.search_news), ("numpy", tracker.search_numpy)):
        for i in range(reps):
            t0 = time.perf_counter()
            path(contacts, st.position, ff.tip_neighbours(st.position), st.step, st.time)
            times[i] = time.perf_counter() - t0
        news[name] = float(np.median(times))

    # frozen A/B: nothing moves, no event can happen. The electrode walls stay on: the tracker
    # takes its planes from them. They push the tips within r* of a plane, which in a few hundred
    # steps of the scene's own dt can carry a tip across a contact's release radius: the frozen
    # scenes take a time step so short that no tip moves measurably (a step costs the same at any dt)
    frozen = ForceParams(ambient_brake=AmbientBrake(coefficient=1e-3), electrodes=params.forces.electrodes)
    # (and a short run.t_end and output.interval, so that the step count stays within the scene's limits)
    still = dataclasses.replace(
        params,
        integrator=dataclasses.replace(params.integrator, dt=1e-9),
        run=dataclasses.replace(params.run, t_end=1e-6),
        output=dataclasses.replace(params.output, interval=1e-6),
    )
    fsims = []
    for enabled in (True, False):
        state = settled.copy()
        state.velocity[:] = 0.0
        fsims.append(Simulation(_with(still, contacts=enabled, forces=frozen), state=state))
    before = len(fsims[0].events)
    frozen_on, frozen_off = np.median(_interleaved(fsims, steps), axis=0)
    assert len(fsims[0].events) == before, "an event happened in the frozen scene"

    ms = 1e3
    pct = 100.0 / step_on_quiet
    print(
        f"\n(a) contact detection + events, {params.rods.count} rods of {scenario_path}; "
        f"{numba.get_num_threads()} numba threads; after {settle} settling steps (t = {sim.state.time:g}, "
        f"{settle_s:.1f} s): {n_contacts} contacts, {len(sim.events)} events so far. "
        f"Medians over {steps} steps; a full step without an event (contacts on) = "
        f"{ms * step_on_quiet:.3f} ms is the 100 %.\n"
    )
    print("| measurement | ms/step | % of a full step |")
    print("|---|---|---|")
    print(f"| full Fig. 2 step, contacts on (all {steps} steps) | {ms * step_on:.3f} | {pct * step_on:.1f} % |")
    print(
        f"| full Fig. 2 step, contacts off, interleaved with the above | {ms * step_off:.3f} | {pct * step_off:.1f} % |"
    )
    print(
        f"| difference on - off (includes the tip list grown to 1.5 r* for the brake) | "
        f"{ms * (step_on - step_off):.3f} | {pct * (step_on - step_off):.1f} % |"
    )
    print(
        f"| difference on (steps without an event) - off | {ms * (step_on_quiet - step_off):.3f} | "
        f"{pct * (step_on_quiet - step_off):.1f} % |"
    )
    print(
        f"| contact search + events in the run, steps without an event ({int(quiet.sum())} steps) | "
        f"{ms * upd_quiet:.3f} | **{pct * upd_quiet:.2f} %** |"
    )
    print(
        f"| ContactTracker.search alone on unchanged positions | {ms * tracker_alone:.3f} | "
        f"{pct * tracker_alone:.2f} % |"
    )
    print(
        f"| ContactTracker on a step with news (the one-pass check not sure): one kernel pass "
        f"(`search_news`) / the numpy passes (`search_numpy`), unchanged positions | "
        f"{ms * news['kernel']:.3f} / {ms * news['numpy']:.3f} | {pct * news['kernel']:.2f} / {pct * news['numpy']:.2f} % |"
    )
    print(
        f"| frozen scene (v = 0, weak ambient brake): step with contacts on - off | "
        f"{ms * (frozen_on - frozen_off):.3f} | {pct * (frozen_on - frozen_off):.2f} % |"
    )
    print(
        f"| (for comparison) contacts + graph + topology + solve on steps with events "
        f"({n_event_steps} steps, {n_events} events) | {ms * upd_event:.3f} | {pct * upd_event:.1f} % |"
    )
    print(f"| (for comparison) mean over all steps, events included | {ms * mean_upd:.3f} | {pct * mean_upd:.1f} % |")


# --------------------------------------------------------------------------- (b)
def _graph_of(n_rods, tc, ct, cid, pot, hold_back):
    """A ConnectivityGraph of the network without the tip contacts ``hold_back`` (row indices)."""
    cond = {
        ev.CONDUCTOR_CATHODE: float(pot[cid == ev.CONDUCTOR_CATHODE][0]),
        ev.CONDUCTOR_ANODE: float(pot[cid == ev.CONDUCTOR_ANODE][0]),
    }
    keep = np.ones(len(tc), dtype=bool)
    keep[hold_back] = False
    arrays = {"tip_contacts": tc[keep], "conductor_tip": ct, "conductor_id": cid, "conductor_potential": pot}
    return ConnectivityGraph.from_arrays(n_rods, cond, arrays)


def graph_update(sizes, batches, repeat, seed):
    rng = np.random.default_rng(seed)
    print(
        f"\n(b) ConnectivityGraph: apply a batch of TIP_CONTACT events, topology(), solve(); "
        f"chains network of selfas_graph/bench/circuit.py; best of {repeat}\n"
    )
    print(
        "| rods | contacts | events in batch | build graph (s) | apply + topology (ms) | topology() after (ms) "
        "| solve (ms) | total (ms) | fresh classify_rods (ms) | filament rods |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|")
    for n in sizes:
        n_rods, tc, ct, cid, pot = chain_network(n, rng)
        for batch in batches:
            batch = min(batch, len(tc))
            pick = rng.choice(len(tc), size=batch, replace=False)
            t0 = time.perf_counter()
            graph = _graph_of(n_rods, tc, ct, cid, pot, pick)
            graph.topology()
            graph.solve()
            build = time.perf_counter() - t0
            add = [(1, 0.1, ev.TIP_CONTACT, int(k), int(l)) for k, l in tc[pick]]
            release = [(2, 0.2, ev.TIP_RELEASE, int(k), int(l)) for k, l in tc[pick]]
            best = dict(apply=np.inf, topo=np.inf, solve=np.inf, total=np.inf, fresh=np.inf)
            for _ in range(repeat):
                t0 = time.perf_counter()
                graph.apply(add)
                t1 = time.perf_counter()
                topo = graph.topology()
                t2 = time.perf_counter()
                sol = graph.solve()
                t3 = time.perf_counter()
                # a fresh classification of the same graph, for reference: the contact set caches its
                # topology (a cached property), so drop it
                graph.contacts.__dict__.pop("topology", None)
                t4 = time.perf_counter()
                graph.topology()
                t5 = time.perf_counter()
                for key, value in (
                    ("apply", t1 - t0),
                    ("topo", t2 - t1),
                    ("solve", t3 - t2),
                    ("total", t3 - t0),
                    ("fresh", t5 - t4),
                ):
                    best[key] = min(best[key], value)
                graph.apply(release)
                graph.topology()
            assert sol.kirchhoff_residual < 1e-9 * max(1.0, sol.total_current)
            print(
                f"| {n_rods} | {len(tc) + len(ct)} | {batch} | {build:.2f} | {1e3 * best['apply']:.1f} | "
                f"{1e3 * best['topo']:.3f} | {1e3 * best['solve']:.1f} | {1e3 * best['total']:.1f} | "
                f"{1e3 * best['fresh']:.1f} | {topo.n_filament} |"
            )


# --------------------------------------------------------------------------- (c)
def _timed(table, name, fn, keep=None):
    """``fn`` wrapped to append its thread CPU time (s) to ``table[name]`` (only for the calls whose
    result ``keep(result)`` accepts, when given)."""
    table.setdefault(name, [])

    def wrapper(*args, **kwargs):
        t0 = time.thread_time()
        out = fn(*args, **kwargs)
        if keep is None or keep(out):
            table[name].append(time.thread_time() - t0)
        return out

    return wrapper


def _simulation_at(scenario_path, settle, checkpoint):
    if checkpoint:
        snap, meta = read_checkpoint(checkpoint)
        import json

        sc = scenario_from_text(meta["scenario_text"], overrides=json.loads(meta["overrides"]))
        return Simulation.from_snapshot(sc.params, snap), f"checkpoint {checkpoint}"
    sim = Simulation(load_scenario(scenario_path).params)
    sim.step(settle)
    return sim, f"{scenario_path} after {settle} steps"


def _patched(calls, graphs, peer_graphs):
    """The functions an event calls, each wrapped to time it: ``[(owner, name, original)]``, patched
    where the run's code looks them up (the contact set's ``classify_rods``, the topology module's
    parts, the network's update and solve, the contact set's apply). The first ``peer_graphs``
    arguments of ``classify_rods`` go to ``graphs``."""
    inner = _timed(calls, "classify_rods", contactset_module.classify_rods)

    def classify(*args):
        if len(graphs) < peer_graphs:
            graphs.append(tuple(np.array(a) if isinstance(a, np.ndarray) else a for a in args))
        return inner(*args)

    patches = [(contactset_module, "classify_rods", classify)]
    for name in ("merge_tips", "component_structures", "filament_rods"):
        patches.append((topology_module, name, _timed(calls, name, getattr(topology_module, name))))
    for owner, name in ((Network, "solve"), (ContactSet, "apply")):
        patches.append((owner, name, _timed(calls, name, getattr(owner, name))))
    # the steps with contact events: the whole of what the network did for each
    patches.append((Network, "update", _timed(calls, "update", Network.update, keep=lambda out: bool(out.events))))
    saved = [(owner, name, getattr(owner, name)) for owner, name, _ in patches]
    for owner, name, fn in patches:
        setattr(owner, name, fn)
    return saved


def events_in_run(scenario_path, settle, checkpoint, steps, peer_graphs):
    sim, origin = _simulation_at(scenario_path, settle, checkpoint)
    sim.step(20)  # compiled kernels, warm caches
    calls: dict[str, list[float]] = {}
    graphs = []
    saved = _patched(calls, graphs, peer_graphs)
    try:
        n_events = len(sim.events)
        t0 = time.process_time()
        sim.step(steps)
        cpu = time.process_time() - t0
    finally:
        for owner, name, fn in saved:
            setattr(owner, name, fn)
    topo = sim.network.topology()
    # the peer: the scipy/networkx classification on the same graphs, checked to agree
    peer, ours = [], []
    for args in graphs:
        t0 = time.thread_time()
        want = oracles.classify_rods_scipy_networkx(*args)
        t1 = time.thread_time()
        got = topology_module.classify_rods(*args)
        t2 = time.thread_time()
        peer.append(t1 - t0)
        ours.append(t2 - t1)
        for name in ("role", "structure", "structure_size"):
            assert np.array_equal(getattr(got, name), getattr(want, name)), f"{name} differs from the peer"

    def per_k(name):
        return 1000.0 * len(calls.get(name, [])) / steps

    def med(name):
        v = calls.get(name, [])
        return 1e3 * float(np.median(v)) if v else float("nan")

    def total(name):
        return float(np.sum(calls.get(name, [])))

    n_cls = len(calls.get("classify_rods", []))
    print(
        f"\n(c) topology and circuit per event, {sim.state.n_rods} rods, from {origin}: {steps} steps "
        f"t = {sim.state.time - steps * sim.dt:.1f} .. {sim.state.time:.1f}, "
        f"{len(sim.events) - n_events} events, {topo.n_filament} filament / {topo.n_dead_end} dead-end / "
        f"{topo.n_cluster} cluster rods at the end; {cpu:.2f} s CPU for the steps "
        f"({1e3 * cpu / steps:.2f} ms/step). Thread CPU time per call, medians.\n"
    )
    print("| part | calls per 1000 steps | ms per call (median) | share of the steps' CPU time |")
    print("|---|---|---|---|")
    for name, label in (
        ("update", "Network.update on a step with events (all of it)"),
        ("apply", "  ContactSet.apply (the new set of contacts)"),
        ("classify_rods", "  classify_rods (all of it)"),
        ("merge_tips", "    tip merge (merge_tips)"),
        ("component_structures", "    components, structures, attachments (one kernel)"),
        ("filament_rods", "    filament search (blocks through X, one kernel)"),
        ("solve", "  Network.solve (circuit)"),
    ):
        calls_k = per_k(name) if name != "merge_tips" else 1000.0 * n_cls / steps
        print(f"| {label} | {calls_k:.1f} | {med(name):.3f} | {100 * total(name) / cpu:.1f} % |")
    if peer:
        p, o = 1e3 * float(np.median(peer)), 1e3 * float(np.median(ours))
        print(
            f"\nOn the first {len(peer)} graphs of these calls (same results checked): classify_rods "
            f"{o:.3f} ms, the scipy/networkx version (selfas_graph/bench/oracles.py) {p:.3f} ms, ratio {p / o:.1f}x."
        )


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default=str(ROOT / "scenarios" / "fig2.toml"))
    ap.add_argument("--settle", type=int, default=2000, help="steps run before measuring (a), to form contacts")
    ap.add_argument("--steps", type=int, default=300, help="timed steps per measurement in (a)")
    ap.add_argument("--sizes", type=int, nargs="+", default=[1000, 10_000, 100_000])
    ap.add_argument("--batch", type=int, nargs="+", default=[10, 1000], help="events per batch in (b)")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--checkpoint", help="(c) start from this checkpoint (read only) instead of the settled scene")
    ap.add_argument("--run-steps", type=int, default=1000, help="steps run in (c)")
    ap.add_argument("--peer-graphs", type=int, default=50, help="graphs of (c) classified again by the peer")
    ap.add_argument("--skip-a", action="store_true")
    ap.add_argument("--skip-b", action="store_true")
    ap.add_argument("--skip-c", action="store_true")
    args = ap.parse_args(argv)
    m = machine()
    print(
        f"{m['cpu_model']} ({m['widest']}, numba target {m['cpu_name']}), python {platform.python_version()}, "
        f"numpy {np.__version__}, numba {numba.__version__}, {os.cpu_count()} CPUs, "
        f"{numba.get_num_threads()} numba threads"
    )
    if not args.skip_a:
        contact_overhead(args.scenario, args.settle, args.steps)
    if not args.skip_b:
        graph_update(args.sizes, args.batch, args.repeat, args.seed)
    if not args.skip_c:
        events_in_run(args.scenario, args.settle, args.checkpoint, args.run_steps, args.peer_graphs)


if __name__ == "__main__":
    for key, value in COMMAND_ENV.items():
        os.environ.setdefault(key, value)
    main()
