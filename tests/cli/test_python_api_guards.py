"""A run file driven from Python keeps what its simulation did and nothing else: a writer refuses a
simulation it cannot continue before any step, a stop or a Ctrl-C hands the buffered rows on, and
arguments that could only fail after a step are refused before it.

The system: three rods in a column across a gap of 3.06 (their tips touch at step 0, so the circuit
closes at once and the run has events to lose)."""

import dataclasses
import gc
import os
import signal
from pathlib import Path

import numpy as np
import pytest

import selfas_graph as sg
from selfas_graph.model.operations import RunInterrupted, When

ROOT = Path(__file__).resolve().parents[2]

PARAMS = sg.Parameters.from_dict(
    {
        "rods": {"count": 3},
        "placement": {"box": [[-3, 3], [-3, 3], [-1.5, 1.5]]},
        "forces": {"tip_magnetic": {}, "tip_brake": {}, "ambient_brake": {}, "electrodes": {"gap": 3.06}},
        "circuit": {"delta_J0": 2.0},
        "output": {"interval": 0.05},
    }
)
CENTRES = [[0, 0, -1.02], [0, 0, 0], [0, 0, 1.02]]


def column(**kw):
    return sg.Simulation(PARAMS, state=sg.State.from_rods(CENTRES, [[0, 0, 1]] * 3, 1.0, 1.0, **kw))


def test_reopen_takes_a_step_not_a_time(tmp_path):
    sim = column()
    with sg.RunWriter.for_simulation(sim, tmp_path / "r.h5") as w:
        sim.run(0.1, writer=w)
    for bad in (0.1, True, -1, "100"):
        with pytest.raises(TypeError, match="an integer >= 0"):
            sg.RunWriter.reopen(tmp_path / "r.h5", step=bad)
    with sg.RunFile(tmp_path / "r.h5") as run:
        assert run.step.tolist() == [0, 50, 100]  # nothing trimmed


def test_a_writer_refuses_another_simulation_before_any_step(tmp_path):
    a, b = column(), column()
    with sg.RunWriter.for_simulation(a, tmp_path / "r.h5") as w:
        a.run(0.1, writer=w)
        with pytest.raises(ValueError, match="its step 0 is before the last step the file holds, 100"):
            b.run(0.1, writer=w)
        assert b.state.step == 0
    with sg.RunFile(tmp_path / "r.h5") as run:
        assert run.time.tolist() == [0.0, 0.05, 0.1]
    four = sg.Simulation(PARAMS.replace(rods={"count": 4}))
    with sg.RunWriter.for_simulation(four, tmp_path / "four.h5") as w:
        with pytest.raises(ValueError, match="the simulation has 6 tips, the file's frames 8"):
            column().run(0.1, writer=w)
    with sg.RunFile(tmp_path / "four.h5") as run:
        assert run.n_frames == 0 and len(run.events()) == 0  # the column's events stayed out of it


def test_a_reopened_file_continues_the_step_it_was_reopened_at(tmp_path):
    sim = column()
    with sg.RunWriter.for_simulation(sim, tmp_path / "r.h5") as w:
        sim.run(0.1, writer=w)
    sim.run(0.2)
    with sg.RunWriter.reopen(tmp_path / "r.h5", step=100) as w:
        with pytest.raises(ValueError, match="reopened to continue after step 100, but the simulation is at step 200"):
            sim.run(0.3, writer=w)


def test_a_reopen_at_a_wrong_step_removes_nothing(tmp_path):
    """``reopen`` at a step before the file's last frame removed the later frames at once, before the
    run that then refused the step: now it is refused first, naming the frames, unless asked for
    (``drop_later=True``, as a resume from a checkpoint); a file open in another writer is refused."""
    sim = column()
    path = tmp_path / "r.h5"
    with sg.RunWriter.for_simulation(sim, path) as w:
        sim.run(0.1, writer=w)
    before = path.read_bytes()
    with pytest.raises(sg.RunFileError, match=r"holds 2 frames \(steps 50 to 100\) after step 12, which reopening"):
        sg.RunWriter.reopen(path, 12)
    assert path.read_bytes() == before
    with sg.RunWriter.reopen(path, 100) as w:
        with pytest.raises(sg.RunFileError, match="open in another writer"):
            sg.RunWriter.reopen(path, 100)
        sim.run(0.2, writer=w)
    with sg.RunWriter.reopen(path, 100, drop_later=True) as w:
        assert w.n_frames == 3
    with sg.RunFile(path) as run:
        assert list(run.step) == [0, 50, 100]


def test_a_stop_hands_the_buffered_rows_and_events_to_the_file(tmp_path):
    sim = column()
    with pytest.raises(RunInterrupted):
        with sg.RunWriter.for_simulation(sim, tmp_path / "r.h5") as w:
            sim.run(0.3, writer=w, stop=lambda: sim.state.step >= 45)
    with sg.RunFile(tmp_path / "r.h5") as run:
        assert len(run.events()) == len(sim.events) > 0
        steps, _ = run.observable("bond_error_per_step")
        assert steps.tolist() == list(range(1, 46))
        assert run.status == "interrupted at step 45"


def test_a_ctrl_c_hands_the_buffered_rows_on_and_says_so(tmp_path):
    sim = column()

    def ctrl_c(sim_, done, total):
        if sim_.state.step >= 30:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        with sg.RunWriter.for_simulation(sim, tmp_path / "r.h5") as w:
            sim.run(0.3, writer=w, progress=ctrl_c, progress_every=10)
    with sg.RunFile(tmp_path / "r.h5") as run:
        assert len(run.events()) == len(sim.events) > 0
        assert run.observable("bond_error_per_step")[0].tolist() == list(range(1, 31))
        assert run.status == "interrupted (Ctrl-C)"


def test_arguments_that_would_fail_after_a_step_are_refused_before_it(tmp_path):
    sim = column()
    with sg.RunWriter.for_simulation(sim, tmp_path / "r.h5") as w:
        sim.run(0.1, writer=w)
    with pytest.raises(sg.RunFileError, match="this writer is closed"):
        sim.run(0.2, writer=w)
    with pytest.raises(TypeError, match=r"run\(progress=...\): a callable"):
        sim.run(0.2, progress=True)
    with pytest.raises(TypeError, match=r"run\(stop=...\): a callable"):
        sim.run(0.2, stop=True)
    with pytest.raises(TypeError, match=r"run\(checkpointer=...\)"):
        sim.run(0.2, checkpointer="ckpt.h5")
    assert sim.state.step == 100
    assert np.isfinite(sim.state.position).all()


@pytest.mark.parametrize(
    "state, message",
    [
        # the nodal solve's currents were 9 % off at this spread, with a Kirchhoff residual of 5e-16
        (dict(resistance=[1, 1e15, 1]), "span 1 to 1e[+]15 R0, a factor above 1e[+]06"),
        (dict(length=0.01), "mean length is 0.01 and the shortest 0.01"),
        (dict(length=2.0), "mean length is 2 and the shortest 2"),
    ],
)
def test_a_state_by_hand_obeys_what_a_scene_file_must(state, message):
    with pytest.raises(sg.StateError, match=message):
        column(**state)
    column(resistance=[1, 1e5, 1])  # within the spread


def test_a_state_by_hand_fits_its_parameters():
    beyond = sg.State.from_rods([[0, 0, -1.02], [0, 0, 0], [0, 0, 10.0]], [[0, 0, 1]] * 3, 1.0, 1.0)
    with pytest.raises(sg.StateError, match=r"tip 4 \(rod 2\) is at z = 9.5, beyond the electrodes at z = \+-1.53"):
        sg.Simulation(PARAMS, state=beyond)
    with pytest.raises(sg.StateError, match="rods.resistance is set in the parameters, but the state has none"):
        sg.Simulation(PARAMS.replace({"rods.resistance": 2.0}), state=column().state)
    with pytest.raises(sg.StateError, match="the state has 3 rods but rods.count = 4"):
        sg.Simulation(PARAMS.replace(rods={"count": 4}), state=column().state)


def test_from_rods_refuses_tips_that_move_apart_and_a_zero_axis():
    axes = [[0, 0, 1]] * 3
    apart = [[0, 0, -1], [0, 0, 1]] * 3  # the first step took the kinetic energy from 3.0 to 0.0005, uncounted
    with pytest.raises(ValueError, match="the tips of rod 0 move apart along its axis at 2"):
        sg.State.from_rods(CENTRES, axes, 1.0, 1.0, velocity=apart)
    spin = np.array([[-0.5, 0, 0], [0.5, 0, 0]] * 3) + [0.1, 0.2, 0.3]  # a drift and a spin: taken
    sim = sg.Simulation(PARAMS, state=sg.State.from_rods(CENTRES, axes, 1.0, 1.0, velocity=spin))
    assert np.array_equal(sim.state.velocity, spin)
    with pytest.raises(ValueError, match="axis of rod 1: zero or not finite"):
        sg.State.from_rods(CENTRES, [[0, 0, 1], [0, 0, 0], [0, 0, 1]], 1.0, 1.0)


def test_a_rod_given_twice_is_refused():
    """At zero distance the regularised laws give no force, so a duplicated rod rode on its copy to
    the end (checked: 50 steps, the two rods' tips equal bit for bit)."""
    axes = [[0, 0, 1], [0, 0, -1], [0, 0, 1]]
    twice = [[0, 0, 0], [0, 0, 0], [0, 0, 1.02]]  # rod 1 is rod 0 the other way round
    with pytest.raises(sg.StateError, match=r"rods 0 and 1 have their tips at the same two points \[0.0, 0.0, -0.5\]"):
        sg.Simulation(PARAMS, state=sg.State.from_rods(twice, axes, 1.0, 1.0))
    # taken: a chain whose tips meet at one point, rods crossing at their centres (the model's rods are lines)
    sg.Simulation(PARAMS, state=sg.State.from_rods([[0, 0, -1], [0, 0, 0], [0, 0, 1]], [[0, 0, 1]] * 3, 1.0, 1.0))
    sg.Simulation(PARAMS, state=sg.State.from_rods(twice, [[0, 0, 1], [1, 0, 0], [0, 0, 1]], 1.0, 1.0))


def test_the_wrong_kind_of_argument_is_named(tmp_path):
    with pytest.raises(TypeError, match=r"Simulation\(state=...\): a State .*, got dict"):
        sg.Simulation(PARAMS, state={"position": []})
    with pytest.raises(TypeError, match="a Scenario .*, got Parameters"):
        sg.Simulation.from_scenario(PARAMS)
    from selfas_graph.analysis.claims import frame_claims

    with pytest.raises(TypeError, match=r"frame_claims\(run, ...\): an open RunFile"):
        frame_claims(str(tmp_path / "r.h5"))
    stretched = column().state
    stretched.position[1, 2] += 0.1
    with pytest.raises(sg.StateError, match=r"rod 0 has length 1.1, not its length 1 \(to"):
        sg.Simulation(PARAMS, state=stretched)


@pytest.mark.parametrize("check_every", [0, -3, 2.5, True])
def test_check_every_is_a_whole_number_of_steps(check_every):
    sim = column()
    with pytest.raises(TypeError, match=r"run\(check_every=...\): a whole number of steps >= 1"):
        sim.run(0.1, stop=lambda: False, check_every=check_every)
    assert sim.state.step == 0


def test_a_run_file_picks_a_frame_by_number_or_time_alike_for_every_array(tmp_path):
    sim = column()
    with sg.RunWriter.for_simulation(sim, tmp_path / "r.h5") as w:
        sim.run(0.1, writer=w)
    with sg.RunFile(tmp_path / "r.h5") as run:
        assert np.array_equal(run.position(t=0.05), run.position(1))
        assert np.array_equal(run.velocity(t=0.1), run.velocity())
        assert run.graph(t=0.05)["step"] == run.step[1]
        with pytest.raises(sg.RunFileError, match=r"events\(until_step=...\): a step number"):
            run.events(until_step="10")


def test_a_snapshot_continued_at_another_time_step_counts_time_on_from_its_own():
    """`bench tradeoff` branches a checkpoint at other time steps: a branch at dt = 2e-3 from step 100 of a
    run at 1e-3 (t = 0.1) stated t = 0.202 after one step (0 + 101 x 2e-3), not 0.102."""
    sim = column()
    sim.run(0.1)
    snap = sim.snapshot()
    same = sg.Simulation.from_snapshot(PARAMS, snap)
    same.step(1)
    assert same.state.time == 0.0 + 101 * 1e-3  # the run's own origin, bit for bit as an uninterrupted run
    other = sg.Simulation.from_snapshot(PARAMS.replace(integrator={"dt": 2e-3}), snap, new_dt=True)
    other.step(1)
    assert other.state.step == 101 and other.state.time == 0.1 + 2e-3
    assert other.integrator.count == 1  # the history at dt = 1e-3 forgotten: the branch starts with RK4


def test_a_snapshot_is_not_continued_at_another_time_step_unasked():
    """A snapshot holds the Adams-Bashforth history of derivatives one dt apart: continued at another dt it
    was extrapolated as if they were the new dt apart, without a word. Refused now, naming both time steps;
    ``new_dt=True`` (`bench tradeoff`'s branches) forgets the history, and a snapshot with none (step 0) is
    taken as it is."""
    sim = column()
    sim.run(0.1)
    with pytest.raises(ValueError, match=r"made with integrator.dt = 0.001, the parameters have 0.002.*new run"):
        sg.Simulation.from_snapshot(PARAMS.replace(integrator={"dt": 2e-3}), sim.snapshot())
    fresh = column().snapshot()
    assert sg.Simulation.from_snapshot(PARAMS.replace(integrator={"dt": 2e-3}), fresh).dt == 2e-3


@pytest.mark.parametrize("name", ["scene.toml", "traj.gsd", "r.checkpoint.h5", "r.failure.h5", "saved.h5"])
def test_overwrite_replaces_a_run_file_only(tmp_path, capsys, name):
    """``overwrite=True`` (``--force``) replaced any file: a scene, an export, another run's checkpoint
    (after which that run could not be resumed, here one copied to another name). It now replaces none
    of them, and no run file takes the name of a run's checkpoint or failed state."""
    import h5py

    from selfas_graph.cli.main import main

    target = tmp_path / name
    if name == "saved.h5":
        with h5py.File(target, "w") as f:  # a checkpoint saved under another name
            f.attrs["format"] = "selfas-graph checkpoint 1"
    elif not name.endswith(".failure.h5"):
        target.write_bytes(b"keep: not a run file")
    before = target.read_bytes() if target.exists() else None
    with pytest.raises(FileExistsError, match="not a run file|the name of a run's checkpoint|a run's checkpoint"):
        sg.RunWriter.for_simulation(column(), target, overwrite=True)
    scene = tmp_path / "s.toml"
    scene.write_text("[rods]\ncount = 2\n[run]\nt_end = 0.01\n")
    assert main(["simulate", str(scene), "-o", str(target), "--force", "--progress", "none"]) == 2
    assert "it is not replaced" in capsys.readouterr().err or name.endswith((".checkpoint.h5", ".failure.h5"))
    assert (target.read_bytes() if target.exists() else None) == before


def test_overwrite_replaces_a_run_file_and_what_is_named_as_one(tmp_path):
    """What ``--force`` is for: an earlier run file, an empty file, a damaged one named ``.h5``."""
    for name in ("run.h5", "empty.h5", "junk.h5"):
        target = tmp_path / name
        if name == "run.h5":
            sg.RunWriter.for_simulation(column(), target).close()
        else:
            target.write_bytes(b"" if name == "empty.h5" else b"not HDF5")
        sg.RunWriter.for_simulation(column(), target, overwrite=True).close()
        with sg.RunFile(target) as run:
            assert run.n_frames == 0


def test_python_mistakes_are_named_by_argument(tmp_path):
    """A path for the writer, a path for frame_topology, a period that is no whole number of steps >= 1,
    a folder or scenario that is no path, one string of overrides: each is refused by its argument (a
    bare AttributeError came through, and Periodic(0) or Periodic(2.7) became another period)."""
    from selfas_graph.analysis.frame_topology import frame_topology
    from selfas_graph.ensemble import Ensemble, EnsembleError

    sim = column()
    with pytest.raises(TypeError, match=r"run\(writer=...\): a writer, RunWriter.for_simulation"):
        sim.run(0.01, writer=str(tmp_path / "x.h5"))
    assert sim.state.step == 0
    with pytest.raises(TypeError, match=r"run\(progress_every=...\): a whole number of steps >= 1"):
        sim.run(0.01, progress=lambda *a: None, progress_every=-2)
    with pytest.raises(TypeError, match="frame_topology.*an open RunFile"):
        frame_topology("run.h5")
    for bad in (0, -3, 2.7, "x", True):
        with pytest.raises(TypeError, match=r"Periodic\(period=...\): a whole number of steps >= 1"):
            sg.Periodic(bad)
    with pytest.raises(TypeError, match=r"When\(predicate"):
        When(5)
    with pytest.raises(TypeError, match=r"load_scenario\(source\): the path of a scenario file"):
        sg.load_scenario(5)
    scene = ROOT / "scenarios" / "quick.toml"
    with pytest.raises(EnsembleError, match="folder: the path of the folder"):
        Ensemble(scene, 2, None)
    with pytest.raises(EnsembleError, match="overrides: give a list of 'key=value' strings"):
        Ensemble(scene, 2, tmp_path / "e", overrides="rods.count=40")
    with pytest.raises(EnsembleError, match=r"t_end \(--t-end\): t_end = 0.0105 is not a whole number of steps"):
        Ensemble(scene, 1, tmp_path / "e", t_end=0.0105)
    assert not (tmp_path / "e").exists()
    loaded = sg.load_scenario(scene, overrides=["rods.count=40"], t_end=0.5)
    Ensemble(loaded, 1, tmp_path / "e")  # a loaded scenario, its end time given at loading
    changed = dataclasses.replace(loaded, params=loaded.params.replace(rods={"count": 30}))
    with pytest.raises(EnsembleError, match="params differ from what its file and overrides give"):
        Ensemble(changed, 1, tmp_path / "e")  # it ran the file's 40 rods without a word


def test_a_writer_refuses_the_frames_of_another_simulation(tmp_path):
    """A writer made for b took a's frames (file: b's seed and charges, a's positions; status "finished"),
    and those of simulations behind the file or elsewhere. Refused now before any step, naming what differs."""
    b = column()
    a = sg.Simulation(PARAMS.replace(scenario={"seed": 2}), state=b.state)
    with sg.RunWriter.for_simulation(b, tmp_path / "r.h5") as w:
        with pytest.raises(ValueError, match="scenario.seed is 1 in the file and 2 in the simulation"):
            a.run(0.1, writer=w)
        assert a.state.step == 0 and w.n_frames == 0
        b.run(0.1, writer=w)
        behind = column()
        behind.run(0.05)
        with pytest.raises(ValueError, match="its step 50 is before the last step the file holds, 100"):
            behind.run(0.3, writer=w)
        moved = dataclasses.replace(b.state, position=b.state.position + 1e-3)
        with pytest.raises(ValueError, match="its positions at step 100 are not those of the file's last frame"):
            sg.Simulation(PARAMS, state=moved).run(0.2, writer=w)
        b.run(0.2, writer=w)  # its own frames, in another call
    with sg.RunFile(tmp_path / "r.h5") as run:
        assert run.step.tolist() == [0, 50, 100, 150, 200]
        assert np.array_equal(run.position(), b.state.position)


def test_a_writer_takes_the_continuation_of_its_simulation(tmp_path):
    """What continues the file is taken: a copy restored from the simulation's snapshot, with the writer open
    or reopened at its step; a reopened file refuses a simulation of other parameters than it states (the end
    time aside) or whose time or positions do not follow it. A writer whose simulation was collected:
    ``test_a_writer_whose_simulation_is_gone_takes_its_continuation_and_nothing_else``."""
    sim = column()
    path = tmp_path / "r.h5"
    with sg.RunWriter.for_simulation(sim, path) as w:
        sim.run(0.1, writer=w)
        copy = sg.Simulation.from_snapshot(PARAMS, sim.snapshot())
        copy.run(0.15, writer=w)
        with pytest.raises(ValueError, match="its step 100 is before the last step the file holds, 150"):
            sim.run(0.2, writer=w)  # the file now holds the copy's frames
    snap = copy.snapshot()
    del sim, copy
    with sg.RunWriter.reopen(path, 150) as w:
        other = sg.Simulation.from_snapshot(PARAMS.replace(circuit={"delta_J0": 3.0}), snap)
        with pytest.raises(ValueError, match="circuit.delta_J0 is 2.0 in the file and 3.0 in the simulation"):
            other.run(0.2, writer=w)
        shifted = sg.Simulation(PARAMS, state=dataclasses.replace(other.state, time=0.5))
        with pytest.raises(ValueError, match="its time 0.5 at step 150 does not follow the last frame's"):
            shifted.run(0.55, writer=w)
        moved = dataclasses.replace(other.state, position=other.state.position + 1e-3)
        with pytest.raises(ValueError, match="its positions at step 150 are not those of the file's last frame"):
            sg.Simulation(PARAMS, state=moved).run(0.2, writer=w)
        again = sg.Simulation.from_snapshot(PARAMS.replace(run={"t_end": 0.2}), snap)
        again.run(writer=w)
    with sg.RunFile(path) as run:
        assert run.step.tolist() == [0, 50, 100, 150, 200] and run.status == "finished"


def test_a_file_written_from_python_states_the_end_time_it_was_run_to(tmp_path):
    """``parameters_json`` states the end time the run was last started or continued with (docs/output.md), as
    ``simulate`` writes it; a file written by ``sim.run(0.1)`` kept the scenario's ``run.t_end``. Chunks
    state the last; a reopened file keeps the end time it stated in ``t_end_before``."""
    import json

    sim = column()
    assert sim.params.run.t_end != 0.15
    path = tmp_path / "r.h5"
    with sg.RunWriter.for_simulation(sim, path) as w:
        sim.run(0.1, writer=w)
        sim.run(np.float32(0.15), writer=w)
    with sg.RunFile(path) as run:
        assert run.parameters["run"]["t_end"] == 0.15 and "t_end_before" not in run.meta
    with sg.RunWriter.reopen(path, sim.state.step) as w:
        sim.run(0.2, writer=w)
        sim.run(0.25, writer=w)
    with sg.RunFile(path) as run:
        assert run.parameters["run"]["t_end"] == 0.25 and json.loads(run.meta["t_end_before"]) == [0.15]


def test_a_writer_judges_a_simulation_by_the_file_not_by_which_objects_are_alive(tmp_path):
    """Whether a simulation continued the file depended on whether the one the writer last took frames from
    was still alive, which garbage collection decides (a simulation holds reference cycles). A copy restored
    from the snapshot of the file's last frame, after a look ahead without the writer, was refused while the
    old object lived; the writer now judges from what it has written, the old object alive or collected."""
    for collect in (False, True):
        sim = column()
        path = tmp_path / f"r{collect}.h5"
        with sg.RunWriter.for_simulation(sim, path) as w:
            sim.run(0.1, writer=w)
            snap = sim.snapshot()  # the state of the file's last frame
            sim.run(0.2)  # a look ahead without the writer
            if collect:
                del sim
                gc.collect()
                assert w._simulation() is None
            sg.Simulation.from_snapshot(PARAMS, snap).run(0.2, writer=w)
        with sg.RunFile(path) as run:
            assert run.step.tolist() == [0, 50, 100, 150, 200]
            steps = run.observable("bond_error_per_step")[0]
            assert steps.tolist() == list(range(1, 201))


def test_a_writer_whose_simulation_is_gone_takes_its_continuation_and_nothing_else(tmp_path):
    """A writer made by ``for_simulation`` whose simulation was dropped and collected took any simulation whose
    time followed the last frame: one behind the file, or one without the events it holds."""
    sim = column()
    w = sg.RunWriter.for_simulation(sim, tmp_path / "r.h5")
    sim.run(0.1, writer=w)
    snap = sim.snapshot()
    del sim
    gc.collect()
    assert w._simulation() is None
    behind = column()
    behind.run(0.05)
    with pytest.raises(ValueError, match="its step 50 is before the last step the file holds, 100"):
        behind.run(0.2, writer=w)
    assert w.events_written > 0
    bare = sg.Simulation(PARAMS, state=sg.State.from_state_dict(snap))  # the state, not the run's event log
    bare.events = []
    with pytest.raises(ValueError, match=f"it holds 0 events, the file {w.events_written}"):
        bare.run(0.2, writer=w)
    sg.Simulation.from_snapshot(PARAMS, snap).run(0.2, writer=w)
    w.close()
    with sg.RunFile(tmp_path / "r.h5") as run:
        assert run.step.tolist() == [0, 50, 100, 150, 200] and run.status == "finished"


def test_a_continuation_from_before_the_rows_a_ctrl_c_wrote_is_refused(tmp_path):
    """A Ctrl-C at step 130 writes the per-step rows to 130, the last frame being at 100. A simulation restored
    from ``last_good_snapshot`` (step 100) was taken once the old one was collected, and the file got the rows
    of steps 101-130 twice. Refused now, alive or collected; a file reopened at 100 with ``drop_later`` takes it."""
    sim = column()
    path = tmp_path / "r.h5"
    w = sg.RunWriter.for_simulation(sim, path)

    def ctrl_c(s, done, total):
        if done == 130:
            os.kill(os.getpid(), signal.SIGINT)

    with pytest.raises(KeyboardInterrupt):
        sim.run(0.2, writer=w, progress=ctrl_c, progress_every=10)
    assert sim.state.step == 130
    good = sim.last_good_snapshot
    assert int(good["step"]) == 100
    for collect in (False, True):
        if collect:
            del sim
            gc.collect()
            assert w._simulation() is None
        with pytest.raises(ValueError, match="its step 100 is before the last step the file holds, 130"):
            sg.Simulation.from_snapshot(PARAMS, good).run(0.2, writer=w)
    w.close()
    with sg.RunWriter.reopen(path, 100, drop_later=True) as w:
        sg.Simulation.from_snapshot(PARAMS, good).run(0.2, writer=w)
    with sg.RunFile(path) as run:
        assert run.step.tolist() == [0, 50, 100, 150, 200]
        assert run.observable("bond_error_per_step")[0].tolist() == list(range(1, 201))


def test_a_state_changed_from_outside_between_steps_is_named_before_the_step():
    """``sim.state.position`` and ``.velocity`` are the arrays the simulation steps in place: a NaN written
    into them, or one tip moved off its rod, is refused before the next step with what was changed, not
    reported after it as a numerical failure that blames the time step or a brake."""
    sim = column()
    sim.step(5)
    sim.state.velocity[3] = np.nan
    with pytest.raises(sg.StateError, match=r"velocity holds NaN or inf at tip 3 \(rod 1\).*changed from outside"):
        sim.step()
    with pytest.raises(sg.StateError, match="changed from outside"):
        sim.run(sim.state.time + 0.01)
    sim.state.velocity[3] = 0.0
    saved = sim.state.position[4].copy()
    sim.state.position[4] = [1e3, 0, 0]
    with pytest.raises(sg.StateError, match=r"tips of rod 2 are .* apart, not its length 1"):
        sim.step()
    sim.state.position[4] = saved
    sim.step(5)  # nothing was failed or stepped: the simulation goes on
    assert sim.failure is None and sim.state.step == 10
