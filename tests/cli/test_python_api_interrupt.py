"""A Ctrl-C in a notebook or script stops ``Simulation.run`` at a step boundary: the state, the event log and
the run file agree with each other, and a run continued from there is the uninterrupted run bit for bit
(docs/output.md "Writing a run file from Python"). A write of the run file cut by an exception is undone.

The interrupts are deterministic: SIGINT sent to this process (``os.kill``) from inside a force evaluation
or a dataset's creation, where a Ctrl-C may land, at a chosen call. The system: the quick scene with 20
rods to t = 0.5 (about 140 of its steps evaluate forces in Python, the rest run compiled)."""

import os
import signal
import threading
import time
from pathlib import Path

import h5py
import numpy as np
import pytest

import selfas_graph as sg
import selfas_graph.io.run_writer as run_writer
from selfas_graph.model.interrupt import DeferredCtrlC

ROOT = Path(__file__).resolve().parents[2]
T_END = 0.5


def quick():
    return sg.Simulation.from_scenario(sg.load_scenario(ROOT / "scenarios/quick.toml", overrides=["rods.count=20"]))


def ctrl_c_at_call(fn, call):
    """``fn`` wrapped to send SIGINT to this process when it is called the ``call``-th time (Ctrl-C)."""
    calls = [0]

    def wrapped(*args, **kwargs):
        calls[0] += 1
        if calls[0] == call:
            os.kill(os.getpid(), signal.SIGINT)
        return fn(*args, **kwargs)

    return wrapped


def rows(path) -> dict:
    """Every dataset of a run file but its provenance (wall times, status), by name."""
    out = {}
    with h5py.File(path, "r") as f:
        f.visititems(lambda name, obj: out.__setitem__(name, obj[()]) if isinstance(obj, h5py.Dataset) else None)
    return {k: v for k, v in out.items() if not k.startswith("parameters")}


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    path = tmp_path_factory.mktemp("ref") / "ref.h5"
    sim = quick()
    with sg.RunWriter.for_simulation(sim, path) as w:
        sim.run(T_END, writer=w)
    return sim, rows(path)


def test_a_ctrl_c_inside_a_step_stops_after_it_and_the_run_continues_bit_for_bit(tmp_path, reference):
    """A Ctrl-C raised inside a force evaluation of step 137 left that step half made (positions moved, the
    Adams-Bashforth history not): ``run()`` again carried on from it, to other positions. It now stops after
    the step, with the file's per-step rows and events up to it, and the continued run is the reference."""
    ref, ref_rows = reference
    sim = quick()
    sim.force_field.evaluate = ctrl_c_at_call(sim.force_field.evaluate, 30)
    w = sg.RunWriter.for_simulation(sim, tmp_path / "r.h5")
    with pytest.raises(KeyboardInterrupt):
        sim.run(T_END, writer=w)
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    stopped = sim.state.step
    assert 0 < stopped < sim.steps_to(T_END) + stopped
    assert w.stopped_by == "interrupted (Ctrl-C)"
    with h5py.File(tmp_path / "r.h5", "r") as f:  # the rows of every step made, and no more
        assert f["observables/bond_error_per_step/step"][-1] == stopped
    sim.run(T_END, writer=w)
    w.close()
    assert np.array_equal(sim.state.position, ref.state.position)
    assert np.array_equal(sim.state.velocity, ref.state.velocity)
    assert sim.events == ref.events
    got = rows(tmp_path / "r.h5")
    assert got.keys() == ref_rows.keys()
    different = [k for k in got if not np.array_equal(got[k], ref_rows[k])]
    assert not different
    with sg.RunFile(tmp_path / "r.h5") as run:
        assert run.status == "finished"


def test_a_ctrl_c_inside_sim_step_stops_after_the_step(reference):
    ref, _ = reference
    sim = quick()
    sim.force_field.evaluate = ctrl_c_at_call(sim.force_field.evaluate, 30)
    n = sim.steps_to(T_END)
    with pytest.raises(KeyboardInterrupt):
        sim.step(n)
    sim.step(n - sim.state.step)
    assert np.array_equal(sim.state.position, ref.state.position)


def test_a_ctrl_c_while_a_frame_is_written_finishes_the_frame(tmp_path, monkeypatch, reference):
    """A Ctrl-C while frame 0's observables were created left a group in the file that the writer had not
    recorded: every later run with the writer failed ("name already exists"). The frame is now finished
    first, and the run stops at step 0 with the file whole."""
    _, ref_rows = reference
    sim = quick()
    with sg.RunWriter.for_simulation(sim, tmp_path / "r.h5") as w:
        # the 7th dataset made after the file's: the 3rd observable's ``step`` dataset
        monkeypatch.setattr(run_writer, "_growable", ctrl_c_at_call(run_writer._growable, 7))
        with pytest.raises(KeyboardInterrupt):
            sim.run(T_END, writer=w)
        assert sim.state.step == 0 and w.n_frames == 1
        sim.run(T_END, writer=w)
    got = rows(tmp_path / "r.h5")
    assert [k for k in got if not np.array_equal(got[k], ref_rows[k])] == []


def test_a_frame_write_cut_by_an_exception_is_undone(tmp_path, monkeypatch):
    """The writer's own guard, for an interrupt that is raised where it lands (a SIGINT handler of the
    caller's, a bug): what the cut frame wrote is removed, and the writer takes the next frames."""
    made = [0]
    growable = run_writer._growable

    def cut(*args, **kwargs):
        made[0] += 1
        if made[0] == 7:
            raise KeyboardInterrupt
        return growable(*args, **kwargs)

    sim = quick()
    with sg.RunWriter.for_simulation(sim, tmp_path / "r.h5") as w:
        monkeypatch.setattr(run_writer, "_growable", cut)
        with pytest.raises(KeyboardInterrupt):
            sim.run(0.1, writer=w)
        assert w.n_frames == 0
        sim.run(0.1, writer=w)
    with sg.RunFile(tmp_path / "r.h5") as run:
        assert run.status == "finished"
        assert run.step.tolist() == [0, 100]  # frames every output.interval = 0.1
        for name in run.observable_names():
            if name != "bond_error_per_step":
                assert len(run.observable(name)[0]) == 2, name


def test_a_sigint_handler_of_the_callers_own_and_other_threads_are_left_alone():
    """run() sets its handler only over Python's default one and in the main thread: a handler the caller
    set (the command line's, a user's) gets the signal, and stays after the run."""
    seen = []

    def mine(signum, frame):
        seen.append(signum)

    before = signal.signal(signal.SIGINT, mine)
    try:
        sim = quick()
        sim.run(0.05, progress=lambda s, i, n: os.kill(os.getpid(), signal.SIGINT) if i == 10 else None)
        assert seen == [signal.SIGINT] and sim.state.time == pytest.approx(0.05)
        assert signal.getsignal(signal.SIGINT) is mine
    finally:
        signal.signal(signal.SIGINT, before)
    errors = []
    other = threading.Thread(target=lambda: errors.append(quick().run(0.05)))
    other.start()
    other.join()
    assert isinstance(errors[0], sg.RunSummary)


def test_a_second_ctrl_c_stops_a_callback_that_hangs_at_once():
    """The first Ctrl-C is held to the end of the step, which a hung step or callback never reaches, and every
    later Ctrl-C was held too: nothing stopped the run. The first now puts Python's handler back, so the second
    raises ``KeyboardInterrupt`` where it lands (a write it cuts is undone), here in the callback's sleep."""
    seen = []

    def hung(sim, done, total):
        if done == 10:
            os.kill(os.getpid(), signal.SIGINT)  # held
            seen.append("held")
            threading.Timer(0.2, os.kill, (os.getpid(), signal.SIGINT)).start()
            time.sleep(10)
            seen.append("slept")

    sim = quick()
    started = time.monotonic()
    with pytest.raises(KeyboardInterrupt):
        sim.run(T_END, progress=hung, progress_every=10)
    assert seen == ["held"] and time.monotonic() - started < 5
    assert sim.state.step == 10
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_a_ctrl_c_after_the_last_check_is_raised_and_the_handler_is_put_back(monkeypatch):
    """A SIGINT after the last check of ``step`` but before its handler was put back was recorded and then
    dropped: ``step`` returned as if none came. ``step`` checks once more after the block, as ``run`` does;
    after both, Python's own handler is in place again."""
    put_back = DeferredCtrlC.__exit__

    def late(self, *exc):
        os.kill(os.getpid(), signal.SIGINT)  # after the last check, the recording handler still in place
        return put_back(self, *exc)

    sim = quick()
    sim.step(2)
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    monkeypatch.setattr(DeferredCtrlC, "__exit__", late)
    with pytest.raises(KeyboardInterrupt):
        sim.step(3)
    assert sim.state.step == 5
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    with pytest.raises(KeyboardInterrupt):
        sim.run(sim.state.time + 10 * sim.dt)
    assert sim.state.step == 15  # the run whole, then the Ctrl-C raised
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
