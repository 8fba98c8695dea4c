"""Contacts, events, short circuit and currents in the run loop (docs/model.md 'Contacts and events', 'Circuit').

Small hand-built scenes with exact expectations: two rods that meet tip to tip,
the contact hysteresis on hand-set positions, a prepared chain of three rods that
closes the gap between the electrodes, and 10^4 contacts recorded in one step.
"""

import time

import numpy as np
import pytest

from conftest import simulation
from selfas_graph.model import events as ev
from selfas_graph.model.contacts import ContactTracker
from selfas_graph.model.contactset import ContactSet
from selfas_graph.model.graph import CLUSTER, FILAMENT
from selfas_graph.model.neighbours import NeighbourList
from selfas_graph.model.state import State

RSTAR = 0.06  # default r* = rod diameter
RELEASE = 1.5 * RSTAR  # default contacts.release_factor * r*
STICKY = {"tip_magnetic": {}, "tip_brake": {}, "ambient_brake": {}}
CURRENT_TERMS = ("current_field", "current_lorentz")


def _kinds(events, kind):
    return [e for e in events if e[2] == kind]


# --------------------------------------------------------------------------- two rods
def _two_rods(gap=0.1, **sections):
    """Rods 0 and 1 on the z axis, tip b of rod 0 (tip 1, -q) facing tip a of rod 1 (tip 2, +q)."""
    state = State.from_rods(
        [[0.0, 0.0, 0.0], [0.0, 0.0, 1.0 + gap]], [[0, 0, 1.0], [0, 0, 1.0]], [1.0, 1.0], [0.0, 0.0]
    )
    sections.setdefault("forces", STICKY)
    sections.setdefault("integrator", {"dt": 1e-3})
    return state, simulation(state, **sections)


def test_two_rods_meet_tip_to_tip_with_one_contact_event():
    """Opposite tips 0.1 apart attract and stick: one TIP_CONTACT (1, 2) at the first step closer than r*.

    With |q_k q_l| = 1 the soft core rests at r*/2 (docs/model.md 'Term 1') and the tip brake
    damps the approach, so the pair never comes back beyond the release radius 1.5 r*:
    no release afterwards, over 600 steps (measured: contact at step 27, then r within
    [0.020, 0.059], ending at 0.030).
    """
    state, sim = _two_rods()
    assert sim.events == []  # 0.1 > r*: nothing in contact at construction
    distance = []
    for _ in range(600):
        sim.step()
        distance.append(np.linalg.norm(state.position[1] - state.position[2]))
    distance = np.array(distance)
    contacts = _kinds(sim.events, ev.TIP_CONTACT)
    assert len(contacts) == 1 and len(sim.events) == 1
    step, t, _, a, b = contacts[0]
    assert (a, b) == (1, 2)
    first_below = int(np.argmax(distance < RSTAR)) + 1  # distance[i] is the state after step i + 1
    assert step == first_below and step > 1
    assert t == pytest.approx(step * 1e-3, abs=1e-12)  # time = step * dt, stamped from the state
    assert not _kinds(sim.events, ev.TIP_RELEASE)
    assert distance[step - 1 :].max() < RELEASE and distance[-1] < RSTAR
    assert sim.contacts.n_contacts == 1 and sim.contact_count() == 1
    assert sim.graph.topology().n_cluster == 2


def test_restart_on_events_resets_the_integrator_history():
    """With integrator.restart_on_events the step of an event leaves an empty AB history.

    The next three steps are RK4 again (count 1, 2, 3), then AB4 resumes (count 4).
    Without the option the history is kept through the event (count stays 4).
    """
    for restart, want in ((True, [0, 1, 2, 3, 4]), (False, [4, 4, 4, 4, 4])):
        _, sim = _two_rods(integrator={"dt": 1e-3, "restart_on_events": restart})
        before = []
        while not sim.events and sim.state.step < 200:  # the contact comes at step 27
            sim.step()
            before.append(sim.integrator.count)
        assert before[-2] == 4  # AB4 was running before the event
        after = [sim.integrator.count]
        for _ in range(4):
            sim.step()
            after.append(sim.integrator.count)
        assert len(sim.events) == 1  # no second event in these steps to reset again
        assert after == want, f"restart_on_events = {restart}"


# --------------------------------------------------------------------------- hysteresis
class _Tracked:
    """A contact search and the contacts it found so far: each update's rows are applied to the
    set (ContactSet.apply), as the network of a run applies them."""

    def __init__(self, n_tips, electrodes=None, filament_radius=None):
        self.search = ContactTracker(n_tips, RSTAR, RELEASE, electrodes, filament_radius)
        conductors = {}
        if electrodes is not None:
            conductors = {ev.CONDUCTOR_CATHODE: -0.5, ev.CONDUCTOR_ANODE: 0.5}
        if filament_radius is not None:
            conductors[ev.CONDUCTOR_FILAMENT] = None
        self.contacts = ContactSet.empty(n_tips // 2, conductors)

    def update(self, position, nl, step, time):
        rows = self.search.search(self.contacts, position, nl, step, time)
        self.contacts = self.contacts.apply(rows)
        return rows

    @property
    def n_contacts(self):
        return self.contacts.n_contacts

    @property
    def pairs(self):
        return self.contacts.tip_contacts

    def __getattr__(self, name):  # on_cathode, on_anode, on_filament
        c = {"on_cathode": ev.CONDUCTOR_CATHODE, "on_anode": ev.CONDUCTOR_ANODE, "on_filament": ev.CONDUCTOR_FILAMENT}
        if name not in c:
            raise AttributeError(name)
        return self.contacts.on_conductor(c[name])


def _tracker_scene(electrodes=None):
    tracker = _Tracked(4, electrodes)
    nl = NeighbourList(RELEASE, 0.3, exclude_same_rod=True)
    return tracker, nl


def test_tip_contact_hysteresis_on_hand_set_positions():
    """A tip contact forms below r*, is held for r* < r < 1.5 r*, and is released beyond 1.5 r*.

    Rods 0 and 1 on the z axis with tips 1 and 2 a distance r apart; the tracker sees
    the positions directly, no dynamics. Distances stay 1e-4 away from the thresholds
    (the comparisons are strict, so exact thresholds would test float rounding).
    """
    tracker, nl = _tracker_scene()
    position = np.zeros((4, 3))

    def update(r, step):
        position[:, 2] = [-1.0, 0.0, r, 1.0 + r]
        nl.update(position)
        return tracker.update(position, nl, step, 0.5 * step)

    expected = [
        (0.100, []),
        (0.0599, [(1, 0.5, ev.TIP_CONTACT, 1, 2)]),
        (0.0601, []),
        (0.0700, []),
        (0.0899, []),  # still held just inside the release radius
        (0.0500, []),
        (0.0899, []),
        (0.0901, [(7, 3.5, ev.TIP_RELEASE, 1, 2)]),
        (0.0700, []),  # between r* and the release radius: no new contact after a release
        (0.0601, []),
        (0.0300, [(10, 5.0, ev.TIP_CONTACT, 1, 2)]),
    ]
    held = []
    for step, (r, rows) in enumerate(expected):
        assert update(r, step) == rows, f"step {step}, r = {r}"
        held.append(tracker.n_contacts)
    assert held == [0, 1, 1, 1, 1, 1, 1, 0, 0, 0, 1]
    np.testing.assert_array_equal(tracker.pairs, [[1, 2]])


def test_electrode_contact_hysteresis_on_hand_set_positions():
    """A tip touches an electrode plane at h < r*, keeps touching for h < 1.5 r*, leaves beyond.

    Planes at z = -1 (cathode, conductor 0) and z = +1 (anode, conductor 1); tip 0 (rod 0)
    at height h above the cathode and tip 3 (rod 1, far away in x) at depth h below the
    anode move together, so each update yields the same event for both conductors,
    releases before contacts and each sorted by tip. A tip pushed beyond the plane (h < 0)
    touches it too.
    """
    tracker, nl = _tracker_scene(electrodes=(-1.0, 1.0))
    position = np.zeros((4, 3))
    position[2:, 0] = 5.0

    def update(h, step):
        position[:, 2] = [-1.0 + h, h, -h, 1.0 - h]
        nl.update(position)
        return tracker.update(position, nl, step, float(step))

    C, R = ev.CONDUCTOR_CONTACT, ev.CONDUCTOR_RELEASE
    expected = [  # (h, event kind or None, touching afterwards)
        (0.10, None, False),
        (0.05, C, True),
        (0.0601, None, True),
        (0.0899, None, True),  # held just inside the release radius
        (0.0901, R, False),
        (0.07, None, False),  # above r*: no new contact after a release
        (-0.01, C, True),  # pushed beyond the plane
        (0.0899, None, True),
        (0.20, R, False),
    ]
    for step, (h, kind, touching) in enumerate(expected):
        rows = update(h, step)
        want = (
            []
            if kind is None
            else [(step, float(step), kind, 0, ev.CONDUCTOR_CATHODE), (step, float(step), kind, 3, ev.CONDUCTOR_ANODE)]
        )
        assert rows == want, f"step {step}, h = {h}"
        assert tracker.on_cathode[0] == touching and tracker.on_anode[3] == touching
        assert not tracker.on_cathode[1:].any() and not tracker.on_anode[:3].any()
    assert tracker.n_contacts == 0  # no tip-tip contact in this scene


def test_release_and_contact_in_one_update_are_ordered():
    """Releases come first, then tip contacts, then electrode contacts, each sorted by ids.

    Four rods along z, moved rigidly between two updates: rod 1 leaves rod 0 (release of
    tips 1-2), rod 3 meets rod 2 (contact of tips 5-6) and rod 1's top tip 3 reaches the
    anode.
    """
    tracker = _Tracked(8, electrodes=(-3.0, 1.25))
    nl = NeighbourList(RELEASE, 0.3, exclude_same_rod=True)
    position = np.zeros((8, 3))
    position[4:, 0] = 5.0
    position[:, 2] = [-1.0, 0.0, 0.03, 1.03, -1.0, 0.0, -0.5, 0.5]  # tips 1-2 touch
    nl.update(position)
    assert tracker.update(position, nl, 0, 0.0) == [(0, 0.0, ev.TIP_CONTACT, 1, 2)]
    position[2:4, 2] += 0.2  # rod 1 up: tips 1-2 0.23 apart, tip 3 0.02 below the anode
    position[6:8, 2] = [0.02, 1.02]  # rod 3 up: tips 5-6 0.02 apart
    nl.update(position)
    assert tracker.update(position, nl, 1, 1.0) == [
        (1, 1.0, ev.TIP_RELEASE, 1, 2),
        (1, 1.0, ev.TIP_CONTACT, 5, 6),
        (1, 1.0, ev.CONDUCTOR_CONTACT, 3, ev.CONDUCTOR_ANODE),
    ]
    np.testing.assert_array_equal(tracker.pairs, [[5, 6]])


# --------------------------------------------------------------------------- prepared chain
GAP = 3.16
DELTA_J0 = 2.0
CHAIN_FORCES = {
    "tip_magnetic": {},
    "tip_brake": {},
    "ambient_brake": {},
    "electrodes": {"gap": GAP},
    "current_field": {},
    "current_lorentz": {},
}


def chain_state(offset=0.005):
    """Three rods along +z stacked tip to tip between electrodes at z = -+GAP/2.

    Tip 0 is 0.025 above the cathode and tip 5 0.025 below the anode (both touch,
    h < r*), tips 1, 2 are 0.03 apart (in contact, the rest distance r*/2 of |q q| = 1),
    tips 3, 4 are 0.08 apart (r* < 0.08: the one missing contact, which the attraction
    of tip 3 (-q) and tip 4 (+q) and the push of both walls close). GAP = 3.16 leaves
    0.05 for each wall once the chain has closed to 3 + 2 r*/2: the end contacts hold.
    The middle rod is shifted by ``offset`` in x: on a perfectly straight chain the
    rods' Biot-Savart fields vanish on the axis and the current terms would be zero.
    """
    z0 = -GAP / 2 + 0.025 + 0.5
    z1 = z0 + 1.03
    z2 = z1 + 1.08
    assert abs(GAP / 2 - (z2 + 0.5) - 0.025) < 1e-12
    return State.from_rods([[0, 0, z0], [offset, 0, z1], [0, 0, z2]], [[0, 0, 1.0]] * 3, [1.0] * 3, [0.0] * 3)


def chain_simulation(offset=0.005, **sections):
    sections.setdefault("forces", CHAIN_FORCES)
    sections.setdefault("circuit", {"delta_J0": DELTA_J0})
    sections.setdefault("integrator", {"dt": 1e-3})
    return simulation(chain_state(offset), **sections)


@pytest.fixture(scope="module")
def chain_run():
    """The chain run up to 5 steps after its short circuit, with a trace of every step."""
    sim = chain_simulation()
    ff = sim.force_field
    trace = [
        dict(
            step=0,
            active=len(ff.active_rod),
            calls=dict(ff.calls),
            solution=sim.solution,
            channel={c: 0.0 for c in CURRENT_TERMS},
        )
    ]
    sc_step = None
    while sim.state.step < 500 and (sc_step is None or sim.state.step < sc_step + 5):
        sim.step()
        trace.append(
            dict(
                step=sim.state.step,
                active=len(ff.active_rod),
                calls=dict(ff.calls),
                solution=sim.solution,
                current=ff.current.copy(),
                channel={c: float(np.abs(ff.out[c]).max()) for c in CURRENT_TERMS},
            )
        )
        if sc_step is None and _kinds(sim.events, ev.SHORT_CIRCUIT):
            sc_step = sim.state.step
    return sim, trace, sc_step


def test_chain_initial_contacts_are_events_of_step_0(chain_run):
    """Contacts present at construction are events of step 0: tips 1-2, tip 0 on the cathode, tip 5 on the anode."""
    sim, _, _ = chain_run
    initial = [e for e in sim.events if e[0] == 0]
    assert initial == [
        (0, 0.0, ev.TIP_CONTACT, 1, 2),
        (0, 0.0, ev.CONDUCTOR_CONTACT, 0, ev.CONDUCTOR_CATHODE),
        (0, 0.0, ev.CONDUCTOR_CONTACT, 5, ev.CONDUCTOR_ANODE),
    ]


def test_chain_closes_the_gap_with_one_short_circuit(chain_run):
    """The attraction closes tips 3-4 within a few hundred steps; that contact is the short circuit.

    Exactly one SHORT_CIRCUIT, at the step of the TIP_CONTACT (3, 4) that completed the
    path cathode - rod 0 - rod 1 - rod 2 - anode, carrying the number of filament rods (3),
    and listed right after it. No release of any kind up to 5 steps later.
    """
    sim, _, sc_step = chain_run
    assert sc_step is not None and 1 < sc_step < 400  # measured: step 14
    short = _kinds(sim.events, ev.SHORT_CIRCUIT)
    assert len(short) == 1
    assert short[0][0] == sc_step and short[0][3:] == (3, -1)
    closing = [e for e in sim.events if e[0] == sc_step]
    assert closing == [(sc_step, closing[0][1], ev.TIP_CONTACT, 3, 4), short[0]]
    assert short[0][1] == closing[0][1] == sim.short_circuit_time
    assert not _kinds(sim.events, ev.TIP_RELEASE) and not _kinds(sim.events, ev.CONDUCTOR_RELEASE)
    assert not _kinds(sim.events, ev.OPEN_CIRCUIT)


def test_chain_short_circuit_is_in_the_circuit_log(chain_run):
    """The circuit log holds one row, made at the SHORT_CIRCUIT step from that step's solve.

    Its total current is the solve's, bit for bit (delta_J0 dZ / 3 R0 through the chain), and
    all three rods are in series: each carries the whole current (counted by hand: one path,
    cathode - rod 0 - rod 1 - rod 2 - anode); filament_rods is the SHORT_CIRCUIT's a (3).
    """
    sim, trace, sc_step = chain_run
    (row,) = sim.circuit_log
    sol = trace[sc_step]["solution"]
    assert row == (sc_step, sim.short_circuit_time, ev.SHORT_CIRCUIT, sol.total_current, 3, 3)
    assert row[3] == pytest.approx(DELTA_J0 * GAP / 3.0, abs=1e-12)  # round-off of one small solve


def test_circuit_log_rows_of_an_open_circuit_and_of_parallel_branches():
    """circuit_rows: an OPEN_CIRCUIT row carries no current and no rods in series; rods in series
    are those whose |J_i| is the total current (a rod on one of two parallel branches is not), and
    other event kinds give no row."""
    from selfas_graph.model.circuitlog import circuit_rows, rods_in_series

    current = np.array([-1.0, 0.5, -0.5, 1.0 - 1e-12, 0.0])  # rods 0 and 3 in series, 1 and 2 parallel
    assert rods_in_series(current, 1.0) == 2
    assert rods_in_series(current, 0.0) == 0
    events = [(7, 0.7, ev.TIP_RELEASE, 3, 4), (7, 0.7, ev.OPEN_CIRCUIT, -1, -1)]
    assert circuit_rows(events, 0.0, np.zeros(5)) == [(7, 0.7, ev.OPEN_CIRCUIT, 0.0, 0, 0)]
    events = [(9, 0.9, ev.TIP_CONTACT, 3, 4), (9, 0.9, ev.SHORT_CIRCUIT, 4, -1)]
    assert circuit_rows(events, 1.0, current) == [(9, 0.9, ev.SHORT_CIRCUIT, 1.0, 2, 4)]


def test_chain_currents_act_from_the_step_after_the_short_circuit(chain_run):
    """No current before the short circuit; delta_J0 dZ / (3 R0) in every chain rod after it, used one step later.

    Before the short-circuit step, force_field.active_rod is empty and the current
    channels are exactly zero. The solve at that step gives each rod
    J = psi(tip a) - psi(tip b) = -(delta_J0 dZ) / 3: the bias delta_J0 dZ between the
    planes (docs/model.md 'Circuit') over three unit resistors, negative because tip a is the
    lower (cathode) end. (For a gap of exactly 3 L this is delta_J0; here dZ = 3.16.)
    Tolerance 1e-12: one sparse solve of a 4-unknown system, round-off only.
    The forces of that step were already computed, so the current channels are still
    zero at the short-circuit step and nonzero from the next one.
    """
    sim, trace, sc_step = chain_run
    J = DELTA_J0 * GAP / 3.0
    for row in trace:
        if row["step"] < sc_step:
            assert row["active"] == 0, row["step"]
            assert row["channel"] == {c: 0.0 for c in CURRENT_TERMS}, row["step"]
    at = trace[sc_step]
    assert at["step"] == sc_step and at["active"] == 3
    np.testing.assert_allclose(at["current"], [-J, -J, -J], rtol=0, atol=1e-12)
    assert at["channel"] == {c: 0.0 for c in CURRENT_TERMS}  # forces of this step predate the solve
    nxt = trace[sc_step + 1]
    for c in CURRENT_TERMS:
        assert nxt["channel"][c] > 0.0, c
    sol = at["solution"]
    assert sol.total_current == pytest.approx(J, abs=1e-12)
    assert sol.effective_resistance == pytest.approx(3.0, abs=1e-12)  # three R0 = 1 rods in series
    assert sol.kirchhoff_residual < 1e-12
    assert sol.dissipated_power == pytest.approx(sol.supplied_power, rel=1e-12)


def test_chain_with_a_gap_of_exactly_three_rods_carries_delta_J0(chain_run):
    """docs/model.md 'Circuit': a straight chain of n rods spanning a gap of n L carries exactly delta_J0.

    The run's chain graph, re-solved with the electrode potentials of dZ = 3 (+-delta_J0 3/2):
    J = delta_J0 in each rod, total current delta_J0, effective resistance 3 R0.
    Tolerance 1e-12: round-off of one small solve.
    """
    from selfas_graph.model.graph import ConnectivityGraph

    sim, _, _ = chain_run
    half = 0.5 * DELTA_J0 * 3.0
    graph = ConnectivityGraph.from_arrays(
        3, {ev.CONDUCTOR_CATHODE: -half, ev.CONDUCTOR_ANODE: half}, sim.graph.arrays()
    )
    sol = graph.solve()
    np.testing.assert_allclose(sol.current, -DELTA_J0, rtol=0, atol=1e-12)
    assert sol.total_current == pytest.approx(DELTA_J0, abs=1e-12)
    assert sol.effective_resistance == pytest.approx(3.0, abs=1e-12)


def test_chain_topology_is_a_filament(chain_run):
    """After the short circuit the three rods form one structure, all FILAMENT; observables agree."""
    sim, _, _ = chain_run
    topo = sim.graph.topology()
    np.testing.assert_array_equal(topo.role, [FILAMENT] * 3)
    assert topo.n_filament == 3 and topo.has_short_circuit
    assert topo.n_structures == 1 and topo.structure_size.tolist() == [3]
    obs = sim.observables()
    assert obs["rods/filament"] == 3 and obs["short_circuit"] == 1.0
    # round-off of one small solve: measured 4.4e-16 and 5.6e-17 (1 ulp each), 1e-14 leaves 20x
    assert obs["total_current"] == pytest.approx(DELTA_J0 * GAP / 3.0, abs=1e-14)
    assert obs["effective_conductance"] == pytest.approx(1 / 3.0, abs=1e-14)


def test_current_terms_cost_nothing_before_the_short_circuit(chain_run):
    """The current kernels are not called while no rod carries current, then once per evaluation.

    ``force_field.calls`` counts kernel calls: current_field / current_lorentz stay 0 up to
    the short-circuit step (the terms are listed, but skip the kernel without currents)
    and grow by at least one per step afterwards, like tip_magnetic. Terms the scene
    does not list are never called: they have no key at all.
    """
    sim, trace, sc_step = chain_run
    for row in trace:
        for c in CURRENT_TERMS:
            if row["step"] <= sc_step:
                assert row["calls"].get(c, 0) == 0, (row["step"], c)
    before, after = trace[sc_step]["calls"], trace[-1]["calls"]
    steps = trace[-1]["step"] - sc_step
    for c in CURRENT_TERMS:
        assert after[c] >= steps
        # every evaluation after the short circuit visits the current kernels
        assert after[c] == after["tip_magnetic"] - before["tip_magnetic"]
    listed = set(CHAIN_FORCES)
    assert set(sim.force_field.calls) <= listed
    for name in ("yukawa", "uniform_field", "plasma_filament", "electric_field"):
        assert name not in sim.force_field.calls


def test_straight_chain_keeps_its_contacts():
    """Without the lateral shift the chain closes the same way and holds all contacts for 500 steps.

    The walls (h = 0.05 < r* at rest) and the tip cores balance; no release, no open
    circuit. This is the state the topology command test writes to a run file.
    """
    sim = chain_simulation(offset=0.0)
    sim.step(500)
    assert len(_kinds(sim.events, ev.SHORT_CIRCUIT)) == 1
    assert not [e for e in sim.events if e[2] in (ev.TIP_RELEASE, ev.CONDUCTOR_RELEASE, ev.OPEN_CIRCUIT)]
    assert sim.graph.topology().n_filament == 3


# --------------------------------------------------------------------------- many events
def test_ten_thousand_contacts_in_one_step():
    """10^4 tip contacts present at construction are 10^4 TIP_CONTACT events of step 0.

    5000 antiparallel pairs of rods side by side (0.03 apart, closer than r*) on a
    100 x 50 grid of spacing 0.5 (beyond the release radius plus the rod length, so
    pairs do not touch each other): in each pair the bottom tips and the top tips touch,
    two contacts per pair, a loop of two rods. The graph then holds 5000 structures of
    two rods, all CLUSTER (no conductor, a loop is not a filament), and a step without
    motion adds no event. The wall-time bound is 10x the measured 1-2 s, so it catches
    an O(events^2) update, not machine noise.
    """
    n_pairs = 5000
    gx, gy = np.meshgrid(np.arange(100) * 0.5, np.arange(50) * 0.5, indexing="ij")
    base = np.stack([gx.ravel(), gy.ravel(), np.zeros(n_pairs)], axis=1)
    centre = np.empty((2 * n_pairs, 3))
    centre[0::2] = base
    centre[1::2] = base + [0.03, 0.0, 0.0]
    axis = np.zeros((2 * n_pairs, 3))
    axis[0::2, 2] = 1.0
    axis[1::2, 2] = -1.0
    state = State.from_rods(centre, axis, np.ones(2 * n_pairs), np.zeros(2 * n_pairs))
    t0 = time.perf_counter()
    sim = simulation(state, forces={})
    elapsed = time.perf_counter() - t0
    assert elapsed < 20.0
    rows = sim.events
    assert len(rows) == 2 * n_pairs == 10_000
    assert all(r[0] == 0 and r[1] == 0.0 and r[2] == ev.TIP_CONTACT for r in rows)
    first = 4 * np.arange(n_pairs)  # tips of rod 2p: 4p, 4p+1; of rod 2p+1 (reversed): 4p+2 (top), 4p+3 (bottom)
    want = np.concatenate([np.stack([first, first + 3], 1), np.stack([first + 1, first + 2], 1)])
    want = want[np.lexsort((want[:, 1], want[:, 0]))]
    np.testing.assert_array_equal(np.array([r[3:] for r in rows]), want)
    np.testing.assert_array_equal(sim.graph.arrays()["tip_contacts"], want)
    assert sim.contacts.n_contacts == 10_000
    topo = sim.graph.topology()
    assert (topo.role == CLUSTER).all() and topo.n_cluster == 2 * n_pairs
    assert topo.n_structures == n_pairs and (topo.structure_size == 2).all()
    np.testing.assert_array_equal(topo.structure[0::2], topo.structure[1::2])
    assert not topo.has_short_circuit
    sim.step()
    assert len(sim.events) == 10_000


def test_quiet_step_kernel_never_hides_an_event(rng, monkeypatch):
    """The one-pass check (kernels/contacts.py::contacts_unchanged) answers True only on steps where the
    full check finds no event: two trackers, with and without it, follow a random walk of tips that
    keeps crossing r*, the release radius, the electrodes and the filament surface, and stay equal."""
    import selfas_graph.model.contacts as contacts_module
    from selfas_graph.kernels.contacts import contacts_unchanged

    n = 160
    position = rng.uniform([-0.4, -0.4, -0.5], [0.4, 0.4, 0.5], size=(n, 3))
    fast = _Tracked(n, electrodes=(-0.45, 0.45), filament_radius=0.3)
    slow = _Tracked(n, electrodes=(-0.45, 0.45), filament_radius=0.3)
    nl = NeighbourList(RELEASE, 0.05, exclude_same_rod=True)
    answers = []
    calls = []
    busy = 0
    monkeypatch.setattr(
        contacts_module, "contacts_unchanged", lambda *a: calls.append(contacts_unchanged(*a)) or calls[-1]
    )
    for step in range(400):
        position += rng.normal(scale=0.004, size=position.shape)
        nl.update(position)
        got = fast.update(position, nl, step, 0.0)
        answers.append(calls[-1])
        with monkeypatch.context() as m:
            m.setattr(contacts_module, "contacts_unchanged", lambda *a: False)
            want = slow.update(position, nl, step, 0.0)
        assert got == want
        np.testing.assert_array_equal(fast.pairs, slow.pairs)
        for flags in ("on_cathode", "on_anode", "on_filament"):
            np.testing.assert_array_equal(getattr(fast, flags), getattr(slow, flags))
        if answers[-1]:
            assert got == []
        busy += bool(got)
    assert 0 < sum(answers) < len(answers) and busy > 50  # both answers exercised, many steps with events


@pytest.mark.parametrize("electrodes, filament_radius", [((-0.45, 0.45), None), (None, None), (None, 0.3)])
def test_news_kernel_finds_the_numpy_paths_events(rng, monkeypatch, electrodes, filament_radius):
    """The step with news by one kernel pass (kernels/contacts.py::contact_news) gives the rows of the
    numpy path (``ContactTracker.search_numpy``, its reference) on every step: two trackers follow a
    random walk of tips that keeps crossing r*, the release radius, the electrodes or the filament
    surface; the kernel must be sure on most steps with news (not falling back on them all)."""
    import selfas_graph.model.contacts as contacts_module
    from selfas_graph.kernels.contacts import contact_news

    n = 160
    position = rng.uniform([-0.4, -0.4, -0.5], [0.4, 0.4, 0.5], size=(n, 3))
    fast = _Tracked(n, electrodes=electrodes, filament_radius=filament_radius)
    slow = _Tracked(n, electrodes=electrodes, filament_radius=filament_radius)
    nl = NeighbourList(RELEASE, 0.05, exclude_same_rod=True)
    sure = []
    monkeypatch.setattr(contacts_module, "contact_news", lambda *a: sure.append(contact_news(*a)) or sure[-1])
    busy = 0
    for step in range(400):
        position += rng.normal(scale=0.004, size=position.shape)
        nl.update(position)
        got = fast.update(position, nl, step, 0.0)
        with monkeypatch.context() as m:
            m.setattr(ContactTracker, "_news", lambda self, *a: None)
            want = slow.update(position, nl, step, 0.0)
        assert got == want
        np.testing.assert_array_equal(fast.pairs, slow.pairs)
        busy += bool(got)
    # a contact within 1e-9 (relative) of r* or the release radius is rare on this walk, so nearly every
    # call is sure; 0.9 fails a kernel that falls back on every step and leaves room for those few
    answers = [s[0] for s in sure]
    assert busy > 50 and sum(answers) > 0.9 * len(answers)


def test_news_kernel_is_not_sure_at_the_thresholds_and_past_its_capacity():
    """A contact within the margin of r* or of the release radius, or more new pairs than
    NEWS_CAPACITY, answers "not sure" (the tracker then takes the numpy path)."""
    from selfas_graph.kernels.contacts import NEWS_CAPACITY, contact_news

    nan = float("nan")
    none = np.zeros(4, dtype=bool)
    for d in (RSTAR, RELEASE):
        position = np.array([[0.0, 0, 0], [5.0, 0, 0], [d, 0, 0], [5.0, 1.0, 0]])
        nl = NeighbourList(RELEASE, 0.3, exclude_same_rod=True)
        nl.update(position)
        pairs = np.array([[0, 2]], dtype=np.int64)
        got = contact_news(position, nl.start, nl.index, pairs, RSTAR, RELEASE, nan, nan, none, none)
        assert not got[0], d
    m = NEWS_CAPACITY + 1  # m rods side by side along x, each pair of neighbours' bottom tips touching
    centre = np.stack([np.arange(2 * m) * 2.5, np.zeros(2 * m), np.zeros(2 * m)], axis=1)
    position = np.empty((4 * m, 3))
    position[0::2] = centre
    position[1::2] = centre + [0.0, 0.0, 1.0]
    position[2::4, 0] = position[0::4, 0] + 0.5 * RSTAR  # tip 4p+2 beside tip 4p
    nl = NeighbourList(RELEASE, 0.3, exclude_same_rod=True)
    nl.update(position)
    flags = np.zeros(4 * m, dtype=bool)
    got = contact_news(position, nl.start, nl.index, np.zeros((0, 2), np.int64), RSTAR, RELEASE, nan, nan, flags, flags)
    assert not got[0]
