"""The Python API: validated parameters and states, exact run ends, run files from Python, event
kinds by name, the top-level names, and the worked example (examples/python_api.py)."""

import dataclasses
import runpy
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

import selfas_graph as sg
from selfas_graph.io.scenario import scenario_from_text

ROOT = Path(__file__).resolve().parents[2]


def test_parameters_replace_and_from_dict_validate_as_scenario_files_do():
    p = sg.Parameters()
    assert p.replace({"integrator.dt": 5e-4}).integrator.dt == 5e-4
    assert p.replace(rods={"count": np.int64(7)}).rods.count == 7  # numpy integers accepted, stored plain
    assert (
        p.replace({"forces.yukawa": True}).forces.yukawa
        == sg.Parameters.from_dict({"forces": {"yukawa": {}}}).forces.yukawa
    )
    assert p.replace({"forces.yukawa": True}).replace({"forces.yukawa": False}).forces.yukawa is None
    assert sg.Parameters.from_dict(p.to_raw()) == p
    # a section object replaces the whole section, its unset values too
    assert p.replace(integrator=dataclasses.replace(p.integrator, dt=2e-3)).integrator.dt == 2e-3
    assert p.replace({"forces.yukawa": True}).replace(forces=p.forces).forces == p.forces
    # None sets an optional value back to its default (it was refused: "expected a number, got None")
    q = p.replace({"rods.transition_radius": 0.1, "neighbours.centre_skin": 0.2})
    assert q.rods.transition_radius == 0.1 and q.neighbours.centre_skin == 0.2
    assert q.replace({"rods.transition_radius": None}, neighbours={"centre_skin": None}) == p
    toml = "[integrator]\ndt = -1.0\n"
    with pytest.raises(sg.ScenarioError) as from_toml:
        scenario_from_text(toml)
    for attempt in (
        lambda: p.replace(integrator={"dt": -1.0}),
        lambda: p.replace({"integrator.dt": -1.0}),
        lambda: sg.Parameters.from_dict({"integrator": {"dt": -1.0}}),
        lambda: dataclasses.replace(p, integrator=dataclasses.replace(p.integrator, dt=-1.0)),
    ):
        with pytest.raises(sg.ScenarioError) as exc:
            attempt()
        assert exc.value.problems == from_toml.value.problems == ["integrator.dt: -1.0 is out of range; valid: > 0"]
    with pytest.raises(sg.ScenarioError, match="rods.count: -5 is out of range"):
        p.replace(rods={"count": -5})
    with pytest.raises(sg.ScenarioError, match="did you mean 'count'"):
        p.replace(rods={"cont": 5})


def test_default_parameters_use_the_split_brake_and_run():
    """The defaults run: the split brake at dt = 1e-3 (the explicit one needs dt <= 5e-4)."""
    p = sg.Parameters()
    assert p.integrator.brake == "split" and p.integrator.dt == 1e-3
    p = p.replace(
        rods={"count": 2},
        placement={"box": [[-1.0, 1.0], [-1.0, 1.0], [-1.0, 1.0]]},
        forces={"tip_magnetic": {}, "tip_brake": {}, "ambient_brake": {}},
    )
    state = sg.State.from_rods([[0.0, 0.0, 0.0], [0.0, 0.0, 1.05]], [[0, 0, 1.0], [0, 0, 1.0]], [1.0, 1.0], [1.0, 1.0])
    sim = sg.Simulation(p, state=state)
    sim.run(1.2)  # past step 1000, where the explicit brake at this dt failed
    assert sim.state.step == 1200 and np.isfinite(sim.state.position).all()


def _rods(n=2):
    centre = np.array([[3.0 * i, 0.0, 0.0] for i in range(n)])
    return sg.State.from_rods(centre, np.tile([0.0, 0.0, 1.0], (n, 1)), np.ones(n), np.ones(n))


def _params(n=2):
    return sg.Parameters().replace(
        rods={"count": n}, forces={"tip_magnetic": {}}, placement={"box": [[-1.0, 3.0 * n], [-1.0, 1.0], [-1.0, 1.0]]}
    )


def test_state_is_validated_and_copied():
    state = _rods()
    before = state.position.copy()
    sim = sg.Simulation(_params(), state=state)
    sim.run(0.01)
    np.testing.assert_array_equal(state.position, before)  # the caller's arrays are untouched
    assert sim.state.position is not state.position

    same_sign = _rods()
    same_sign.tip_charge[1] = 1.0
    with pytest.raises(sg.StateError, match="rod 0 has tip charges 1 and 1"):
        sg.Simulation(_params(), state=same_sign)
    stretched = _rods()
    stretched.position[3, 2] += 0.01  # rod 1 of length 1.01
    with pytest.raises(sg.StateError, match="rod 1 has length 1.01"):
        sg.Simulation(_params(), state=stretched)
    nan = _rods()
    nan.velocity[2, 0] = np.nan
    with pytest.raises(sg.StateError, match="non-finite"):
        sg.Simulation(_params(), state=nan)
    with pytest.raises(sg.StateError, match=r"the state has 2 rods but rods.count = 3"):
        sg.Simulation(_params(3), state=_rods(2))
    for step in (1.5, True, "2"):  # 1.5 was cut to step 1 without a word
        with pytest.raises(sg.StateError, match="State.step: a whole number of steps >= 0, got"):
            sg.Simulation(_params(), state=dataclasses.replace(_rods(), step=step))
    assert sg.Simulation(_params(), state=dataclasses.replace(_rods(), step=np.int64(7))).state.step == 7


def test_run_lands_on_t_end_or_refuses():
    p = _params().replace(integrator={"dt": 8e-3})
    sim = sg.Simulation(p, state=_rods())
    with pytest.raises(ValueError, match=r"not a whole number of steps .* nearest reachable times are 0.496 and 0.504"):
        sim.run(0.5)
    assert sim.state.step == 0
    sim.run(0.496)
    assert sim.state.step == 62 and sim.state.time == pytest.approx(0.496, abs=1e-15)
    with pytest.raises(ValueError, match="before the current time"):
        sim.run(0.2)
    with pytest.raises(ValueError, match="before the current time"):  # not "the nearest reachable times" in the past
        sim.run(0.3)
    sim.run(0.496)  # no step
    assert sim.state.step == 62


def test_cli_refuses_an_unreachable_t_end(tmp_path, capsys):
    scene = tmp_path / "s.toml"
    scene.write_text("[rods]\ncount = 2\n[integrator]\ndt = 8e-3\n[run]\nt_end = 0.5\n")
    assert sg_main(["simulate", str(scene), "-o", str(tmp_path / "s.h5"), "--progress", "none"]) == 2
    assert "run.t_end" in capsys.readouterr().err
    assert not (tmp_path / "s.h5").exists()


def sg_main(argv):
    from selfas_graph.cli.main import main

    return main(argv)


def test_run_file_from_python_with_event_names(tmp_path):
    sim = sg.Simulation(_params(), state=_rods())
    out = tmp_path / "py.h5"
    with sg.RunWriter.for_simulation(sim, out) as w:
        sim.run(0.05, writer=w)
        sim.run(0.1, writer=w)
    with pytest.raises(FileExistsError, match="pass overwrite=True to overwrite it, or another path") as info:
        sg.RunWriter.for_simulation(sim, out)
    assert "--force" not in str(info.value)  # Python's advice names Python's argument
    with sg.RunFile(out) as run:
        assert run.meta["status"] == "finished"
        assert run.step[-1] == 100 and run.parameters["rods"]["count"] == 2
    assert sg.EventKind.SHORT_CIRCUIT == 5 and sg.EventKind(1).label == "tip_contact"


def test_a_run_file_opened_mid_run_says_it_reads_the_frames_it_found(tmp_path):
    """A notebook cell opens the run, the next continues it: the open RunFile keeps the frames it found,
    and asking for a later one said the file had only those; it now says more were written since."""
    sim = sg.Simulation(_params(), state=_rods())
    out = tmp_path / "nb.h5"
    with sg.RunWriter.for_simulation(sim, out) as w:
        sim.run(0.05, writer=w)
        run = sg.RunFile(out)
        n = run.n_frames
        sim.run(0.1, writer=w)
        with pytest.raises(sg.RunFileError, match=f"frames 0..{n - 1} when this RunFile was opened; the file holds"):
            run.position(n + 1)
        assert run.n_frames == n  # the frames it found, as its docstring says
        run.close()
    with sg.RunFile(out) as again:
        assert again.n_frames > n


def test_a_writer_used_wrongly_is_refused_and_the_file_stays_readable(tmp_path):
    """A closed writer handed to ``sim.run`` gave a TypeError from deep inside; a writer made for
    another simulation wrote part of a frame and left the file unreadable. Both are refused by name
    before anything is written, and the file keeps its frames."""
    sim = sg.Simulation(_params(), state=_rods())
    out = tmp_path / "py.h5"
    with sg.RunWriter.for_simulation(sim, out) as w:
        sim.run(0.02, writer=w)
        other = sg.Simulation(_params(3), state=_rods(3))
        with pytest.raises(ValueError, match="made for another simulation"):
            other.run(0.02, writer=w)
    with pytest.raises(sg.RunFileError, match="this writer is closed"):
        sim.run(0.04, writer=w)
    with sg.RunFile(out) as run:
        assert list(run.step) == [0, 20] and run.position(-1).shape == (4, 3)


def test_run_file_reads_refuse_by_name(tmp_path):
    """A group of observables (``energy``), a frame number that is not an integer and a read after the
    file was closed gave raw h5py errors or took the integer part; each is a RunFileError now."""
    sim = sg.Simulation(_params(), state=_rods())
    out = tmp_path / "r.h5"
    with sg.RunWriter.for_simulation(sim, out) as w:
        sim.run(0.04, writer=w)
    with sg.RunFile(out) as run:
        assert "energy/kinetic" in run.observable_names()
        with pytest.raises(sg.RunFileError, match="no observable 'energy'; present: .*energy/kinetic"):
            run.observable("energy")
        with pytest.raises(sg.RunFileError, match="give a frame number"):
            run.position(1.7)
        first = run.position(0)
    with pytest.raises(sg.RunFileError, match="the run file is closed"):
        run.position(0)
    assert first.shape == (4, 3)


def test_objects_of_the_wrong_kind_are_refused_by_name():
    """A dict for the parameters, a path for a loaded scenario and a string of changes gave
    AttributeErrors from inside; each names what to give instead."""
    with pytest.raises(TypeError, match=r"Simulation\(params\): a Parameters .*got dict"):
        sg.Simulation({"rods": {"count": 3}})
    with pytest.raises(TypeError, match=r"from_scenario: a Scenario \(load_scenario\), got"):
        sg.Simulation.from_scenario("scenarios/quick.toml")
    with pytest.raises(TypeError, match="changes by dotted key in a dict"):
        sg.Parameters().replace("integrator.dt=5e-4")


def test_step_count_and_overrides_are_checked():
    """``step(n)`` took -3 as nothing and 2.5 as three steps; a string of overrides was read one
    character at a time, and a string of seeds digit by digit."""
    sim = sg.Simulation(_params(), state=_rods())
    for bad, kind in ((-3, ValueError), (2.5, TypeError), ("3", TypeError)):
        with pytest.raises(kind, match="Simulation.step"):
            sim.step(bad)
    sim.step(np.int64(2))
    assert sim.state.step == 2
    quick = Path(__file__).resolve().parents[2] / "scenarios" / "quick.toml"
    for bad in ("integrator.dt=5e-4", None):
        with pytest.raises(sg.ScenarioError, match="overrides: give a list"):
            sg.load_scenario(quick, overrides=bad)
    from selfas_graph.ensemble import Ensemble, EnsembleError

    for seeds in ("12", 2.0, [1.5]):
        with pytest.raises(EnsembleError, match="seeds: give a count N or a list of integer seeds"):
            Ensemble(quick, seeds, "never_made")
    with pytest.raises(EnsembleError, match=r"first_seed \(--first-seed\) 100 goes with a count of seeds"):
        Ensemble(quick, [5], "never_made", first_seed=100)  # it ran seed 5 alone
    assert Ensemble(quick, 2, "never_made", first_seed=100).seeds == [100, 101]
    assert not Path("never_made").exists()


def test_event_kind_is_an_enumeration_in_the_file(tmp_path):
    from selfas_graph.io.h5md import RunWriter

    w = RunWriter(tmp_path / "e.h5", 4, np.ones(4), np.ones(2), {"parameters_json": "{}"})
    w.write_events([(3, 0.3, sg.EventKind.TIP_CONTACT, 1, 2), (4, 0.4, 5, 2, -1)])
    w.close()
    with h5py.File(tmp_path / "e.h5", "r") as f:
        names = h5py.check_enum_dtype(f["events"].dtype["kind"])
        assert names == {e.label: int(e) for e in sg.EventKind}


def test_top_level_names():
    for name in (
        "solve_circuit",
        "parameters_from_dict",
        "load_scenario",
        "Simulation",
        "State",
        "RunFile",
        "RunWriter",
        "export_run",
        "EventKind",
        "named_events",
        "ROLE_NAMES",
        "Parameters",
        "Operation",
        "Periodic",
        "Always",
        "When",
        "RunInterrupted",
    ):
        assert name in sg.__all__ and hasattr(sg, name)
    assert set(sg.__all__) <= set(dir(sg))
    assert sg.model.state.State is sg.State and sg.io.h5md.RunFile is sg.RunFile
    with pytest.raises(AttributeError, match="no attribute 'Simulaton'"):
        sg.Simulaton


def test_the_package_and_the_command_line_import_the_heavy_libraries_on_first_use():
    """The command line imports numba and the rest inside its handling of a Ctrl-C (cli/main.py::main):
    the API's names are imported when first used (``selfas_graph.__getattr__``)."""
    import subprocess

    code = (
        "import sys, selfas_graph as sg, selfas_graph.cli.main\n"
        "print([m for m in ('numba', 'h5py', 'scipy', 'networkx', 'mpi4py') if m in sys.modules])\n"
        "sg.Simulation\n"
        "print('numba' in sys.modules)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.split() == ["[]", "True"]


def test_worked_example_runs(tmp_path, monkeypatch, capsys):
    out = tmp_path / "column.h5"
    monkeypatch.setattr(sys, "argv", ["python_api.py", str(out)])
    runpy.run_path(str(ROOT / "examples" / "python_api.py"), run_name="__main__")
    text = capsys.readouterr().out
    assert "refused: integrator.dt" in text and "short_circuit" in text and "'filament'" in text
    with sg.RunFile(out) as run:
        assert run.n_frames == 7 and (run.graph(-1)["role"][:3] == 3).all()


def _two_rod_run(tmp_path):
    """A finished run of two rods to t = 0.01 (its checkpoint beside it): the run file's path."""
    scene = tmp_path / "s.toml"
    scene.write_text(
        "[rods]\ncount = 2\n[forces.tip_magnetic]\n[forces.tip_brake]\n[run]\nt_end = 0.01\n"
        "[output]\ninterval = 0.005\ncheckpoint_interval = 0\n"
    )
    out = tmp_path / "s.h5"
    assert sg_main(["simulate", str(scene), "-o", str(out), "--progress", "none"]) == 0
    return out


def test_resume_keeps_the_brake_a_run_started_with(tmp_path):
    """A scene without integrator.brake started when the default was explicit resumes explicit."""
    import json

    from selfas_graph.io.checkpoint import checkpoint_path, read_checkpoint

    out = _two_rod_run(tmp_path)
    with h5py.File(out, "r+") as f:  # as a run file of that time says
        attrs = f["parameters/selfas_graph"].attrs
        resolved = json.loads(attrs["parameters_json"])
        resolved["integrator"]["brake"] = "explicit"
        attrs["parameters_json"] = json.dumps(resolved)
    assert sg_main(["simulate", "--resume", str(out), "--t-end", "0.02", "--progress", "none"]) == 0
    _, meta = read_checkpoint(checkpoint_path(out))
    assert json.loads(meta["overrides"]) == ["integrator.brake=explicit"]


def test_an_ensemble_seed_resumes_as_simulate_does(tmp_path):
    """An ensemble's seed continues through the checks of simulate --resume (lifecycle.continuation): a
    run started when the brake's default was explicit resumes explicit, and the checkpoints from then on
    say so and name this version, as simulate's do (the seed kept the old checkpoint's record)."""
    import json

    from selfas_graph import __version__
    from selfas_graph.ensemble import run_seed
    from selfas_graph.io.checkpoint import checkpoint_path, read_checkpoint, write_checkpoint

    out = _two_rod_run(tmp_path)
    ckpt = checkpoint_path(out)
    snap, meta = read_checkpoint(ckpt)
    write_checkpoint(ckpt, snap, {**meta, "version": "0.0.1"})
    with h5py.File(out, "r+") as f:  # as a run file of that time says
        attrs = f["parameters/selfas_graph"].attrs
        resolved = json.loads(attrs["parameters_json"])
        resolved["integrator"]["brake"] = "explicit"
        attrs["parameters_json"] = json.dumps(resolved)
    res = run_seed({"seed": 1, "path": str(out), "action": "resume", "t_end": 0.02})
    assert res["status"] == "finished", res
    _, meta = read_checkpoint(ckpt)
    assert json.loads(meta["overrides"]) == ["integrator.brake=explicit"] and meta["version"] == __version__
    assert meta["t_end"] == 0.02


def test_resume_by_another_version_is_noted_and_recorded(tmp_path, capsys):
    """A checkpoint written by another version is continued with a note that names both versions, and
    the run file records the continuation's version in ``resumed_with``."""
    import json

    from selfas_graph import __version__
    from selfas_graph.io.checkpoint import checkpoint_path, read_checkpoint, write_checkpoint

    out = _two_rod_run(tmp_path)
    ckpt = checkpoint_path(out)
    snap, meta = read_checkpoint(ckpt)
    write_checkpoint(ckpt, snap, {**meta, "version": "0.0.1"})
    with h5py.File(out, "r+") as f:  # the run file of that version
        f["parameters/selfas_graph"].attrs["version"] = "0.0.1"
    capsys.readouterr()
    assert sg_main(["simulate", "--resume", str(out), "--t-end", "0.02", "--progress", "none"]) == 0
    err = capsys.readouterr().err
    assert f"was written by version 0.0.1 and version {__version__} continues it" in err
    with sg.RunFile(out) as run:
        assert run.meta["version"] == "0.0.1"
        assert [r["version"] for r in json.loads(run.meta["resumed_with"])] == [__version__]
    capsys.readouterr()
    assert sg_main(["simulate", "--resume", str(out), "--t-end", "0.03", "--progress", "none"]) == 0
    assert "was written by version" not in capsys.readouterr().err  # its own checkpoint now


def test_sections_given_as_dicts_and_numpy_scalars():
    """A section given as a dict to ``Parameters(...)`` or ``dataclasses.replace`` is named (it failed
    deep in the simulation); numpy scalars from a notebook are taken as the numbers they print as: a
    float32 dt of 1e-3 is 0.001 (not 0.0010000000474974513, which no t_end of whole steps matched)."""
    import dataclasses

    for make in (
        lambda: sg.Parameters(rods={"count": 5}),
        lambda: dataclasses.replace(sg.Parameters(), rods={"count": 5}),
    ):
        with pytest.raises(sg.ScenarioError, match=r"rods: a dict where the section's parameters \(RodParams\)"):
            make()
    p = _params().replace(integrator={"dt": np.float32(1e-3)}, contacts={"enabled": np.True_})
    assert p.integrator.dt == 0.001 and p.contacts.enabled is True
    sim = sg.Simulation(p, state=_rods())
    sim.run(0.01)
    assert sim.state.step == 10


def _failing_quick():
    """The quick scene with an ambient brake too stiff for its step: a numerical failure at step 18."""
    scene = sg.load_scenario(ROOT / "scenarios" / "quick.toml", overrides=["forces.ambient_brake.coefficient=1e3"])
    return sg.Simulation.from_scenario(scene)


def test_a_failure_inside_a_writer_block_keeps_the_rows_up_to_it_and_the_file_says_failed(tmp_path):
    """A numerical failure in ``sim.run`` inside ``with RunWriter...``: the per-step rows and events up to
    the failing step reach the file, as through the command line (the rows since the last frame were
    lost), and the file says "failed"; a failure caught inside the block, and a plain ``close()`` after
    it, no longer mark the run "finished"."""
    sim = _failing_quick()
    out = tmp_path / "a.h5"
    with pytest.raises(sg.NumericalFailure) as failure:
        with sg.RunWriter.for_simulation(sim, out) as w:
            sim.run(1.0, writer=w)
    step = failure.value.step
    with sg.RunFile(out) as run:
        assert run.meta["status"].startswith(f"failed: numerical failure at step {step} ")
    with h5py.File(out, "r") as f:
        rows = f["observables/bond_error_per_step/step"][:]
        assert rows[-1] == step - 1 and len(rows) == step - 1  # every step before the failing one
        assert len(f["events"]) == len(sim.events)
    for caught in ("in the block", "then close()"):
        sim = _failing_quick()
        w = sg.RunWriter.for_simulation(sim, tmp_path / f"{caught}.h5")
        with pytest.raises(sg.NumericalFailure):
            sim.run(1.0, writer=w)
        if caught == "then close()":
            w.close()
        else:
            w.__exit__(None, None, None)
        with sg.RunFile(tmp_path / f"{caught}.h5") as run:
            assert run.meta["status"].startswith("failed: numerical failure at step"), caught


@pytest.mark.parametrize("where", ["progress", "operation"])
def test_an_error_in_the_users_own_code_keeps_the_rows_up_to_it(tmp_path, where):
    """A bug in a progress callback or an attached operation stops ``sim.run``: the events and per-step
    rows of the steps taken reach the file (only Ctrl-C and a numerical failure flushed them: 0 of 250
    rows were kept), and a plain ``close()`` records the error, named by its type."""
    sim = sg.Simulation.from_scenario(sg.load_scenario(ROOT / "scenarios" / "quick.toml"))

    def bug(sim, *args):
        if sim.state.step >= 250:
            raise ValueError("bug in my code")

    class Buggy(sg.Operation):
        trigger = sg.Periodic(50)
        act = staticmethod(bug)

    if where == "operation":
        sim.operations.append(Buggy())
    w = sg.RunWriter.for_simulation(sim, tmp_path / "a.h5")
    with pytest.raises(ValueError, match="bug in my code"):
        sim.run(1.0, writer=w, **({"progress": bug, "progress_every": 50} if where == "progress" else {}))
    w.close()
    with sg.RunFile(tmp_path / "a.h5") as run:
        assert run.meta["status"] == "failed: ValueError: bug in my code"
    with h5py.File(tmp_path / "a.h5", "r") as f:
        assert len(f["observables/bond_error_per_step/step"]) == 250 == sim.state.step
        assert len(f["events"]) == len(sim.events)
    # the writer as a context manager records the same status (it recorded "failed: bug in my code")
    again = sg.Simulation.from_scenario(sg.load_scenario(ROOT / "scenarios" / "quick.toml"))
    if where == "operation":
        again.operations.append(Buggy())
    with pytest.raises(ValueError), sg.RunWriter.for_simulation(again, tmp_path / "b.h5") as w:
        again.run(1.0, writer=w, **({"progress": bug, "progress_every": 50} if where == "progress" else {}))
    with sg.RunFile(tmp_path / "b.h5") as run:
        assert run.meta["status"] == "failed: ValueError: bug in my code"


def test_a_failed_simulation_refuses_more_steps_and_its_file_keeps_the_first_failure(tmp_path):
    """After a NumericalFailure the simulation held the failed state and stepped on from it (NaN by
    the third retry), each retry recording a later failure in the file in place of the first: run and
    step now refuse, naming the failure and the way on (from the last good snapshot)."""
    sim = _failing_quick()
    w = sg.RunWriter.for_simulation(sim, tmp_path / "a.h5")
    with pytest.raises(sg.NumericalFailure) as first:
        sim.run(1.0, writer=w)
    for again in (lambda: sim.run(1.0, writer=w), lambda: sim.step(1)):
        with pytest.raises(RuntimeError, match=rf"stopped at step {first.value.step} .*last_good_snapshot"):
            again()
    w.close()
    with sg.RunFile(tmp_path / "a.h5") as run:
        assert run.meta["status"].startswith(f"failed: numerical failure at step {first.value.step} ")
    good = sg.Simulation.from_snapshot(sim.params, sim.last_good_snapshot)
    assert good.failure is None and good.state.step < first.value.step


def test_a_writer_no_run_wrote_to_says_so(tmp_path):
    """A writer closed before any run (or after a refused one) said "finished"; a new file now says
    "no run written", a reopened one keeps the status it had."""
    sim = sg.Simulation(_params(), state=_rods())
    with sg.RunWriter.for_simulation(sim, tmp_path / "a.h5"):
        pass
    with sg.RunFile(tmp_path / "a.h5") as run:
        assert run.meta["status"] == "no run written"
    with sg.RunWriter.for_simulation(sim, tmp_path / "b.h5") as w:
        sim.run(0.05, writer=w)
    sg.RunWriter.reopen(tmp_path / "b.h5", 50).close()
    with sg.RunFile(tmp_path / "b.h5") as run:
        assert run.meta["status"] == "finished"


def test_a_later_run_that_ends_well_closes_finished(tmp_path):
    """The reason a run stopped early is that run's: a next ``sim.run`` on the writer that ends well
    leaves a plain ``close()`` saying "finished"."""
    sim = sg.Simulation(_params(), state=_rods())
    with sg.RunWriter.for_simulation(sim, tmp_path / "b.h5") as w:
        w.stopped_by = "failed: an earlier run"
        sim.run(0.02, writer=w)
    with sg.RunFile(tmp_path / "b.h5") as run:
        assert run.meta["status"] == "finished"


@pytest.mark.parametrize("t_end", ["inf", "nan", "1e300"])
def test_resume_to_an_impossible_end_time_blames_the_end_time(tmp_path, capsys, t_end):
    """``--resume --t-end inf`` said the checkpoint's scenario no longer validates; the checkpoint is fine,
    the end time asked for is not."""
    out = _two_rod_run(tmp_path)
    capsys.readouterr()
    assert sg_main(["simulate", "--resume", str(out), "--t-end", t_end, "--progress", "none"]) == 2
    err = capsys.readouterr().err
    assert f"cannot resume to the end time {float(t_end)!r} asked for (--t-end, run.t_end)" in err
    assert "no longer validates" not in err and "run.t_end" in err
