"""The bugs the hostile-input tests (tests/validation/test_hostile.py) found, each pinned with its input and the
expected behaviour; all fixed. A new one is added here, marked ``xfail(strict=True)`` until it is fixed.

The contract is that of tests/validation/test_hostile.py: bad input gives exit code 2 and a message naming the
problem, a numerical failure exit code 3, never a traceback, and no existing file is damaged.
"""

from __future__ import annotations

import copy
import os

import h5py
import numpy as np
import pytest

from hostile import (
    BASE,
    BASE_TEXT,
    Result,
    check_contract,
    cli,
    non_finite_datasets,
    scenario_file,
    to_toml,
    tree,
)
from selfas_graph.io.checkpoint import FORMAT as CHECKPOINT_FORMAT
from selfas_graph.io.checkpoint import checkpoint_path


def _expect_usage_error(res: Result, *words):
    check_contract(res, allowed=(2,))
    for w in words:
        assert w in res.err


def test_bug_huge_placement_box(workdir, capsys):
    scen = scenario_file(workdir, placement={"box": [[-1e200, 1e200], [-1.0, 1.0], [-1.0, 1.0]]})
    _expect_usage_error(cli(capsys, "simulate", scen, "--dry-run"), "placement.box")


def test_bug_tiny_placement_box(workdir, capsys):
    scen = scenario_file(workdir, placement={"box": [[0.0, 1e-300], [0.0, 1e-300], [0.0, 1e-300]]})
    _expect_usage_error(cli(capsys, "simulate", scen, "--dry-run"), "placement.box")


def test_bug_huge_min_tip_distance(workdir, capsys):
    scen = scenario_file(workdir, placement={"min_tip_distance": 1e300})
    _expect_usage_error(cli(capsys, "simulate", scen, "--dry-run"), "min_tip_distance")


@pytest.mark.parametrize("term", ["current_lorentz", "external_dipole"])
def test_bug_huge_quadrature_points(term, workdir, capsys):
    res = cli(
        capsys,
        "simulate",
        scenario_file(workdir),
        "--dry-run",
        f"--set=forces.{term}.quadrature_points=9223372036854775807",
    )
    _expect_usage_error(res, "quadrature_points")


@pytest.mark.parametrize(
    "args",
    [["--set=integrator.dt=5e-324"], ["--t-end=1.7e308"], ["--set=integrator.dt=1e-10", "--set=output.interval=1e300"]],
)
def test_bug_step_count_overflow(args, workdir, capsys):
    check_contract(cli(capsys, "simulate", scenario_file(workdir), "--dry-run", *args), allowed=(2,))


def test_bug_huge_rod_count(workdir, capsys):
    scen = scenario_file(workdir, rods={"count": 10**12}, placement={"min_tip_distance": 0.0})
    _expect_usage_error(cli(capsys, "simulate", scen, "--dry-run"), "rods.count")


def test_bug_seed_beyond_64_bits(workdir, capsys):
    out = workdir / "out.h5"
    res = cli(capsys, "simulate", scenario_file(workdir, scenario={"seed": 2**64}), "-o", out, "--progress", "none")
    check_contract(res, allowed=(0, 2))
    assert out.exists() == (res.code == 0)


def test_bug_huge_output_interval(workdir, capsys):
    out = workdir / "out.h5"
    res = cli(capsys, "simulate", scenario_file(workdir, output={"interval": 1e300}), "-o", out, "--progress", "none")
    check_contract(res, allowed=(0, 2))
    assert out.exists() == (res.code == 0)


def test_bug_huge_neighbour_skin(workdir, capsys):
    res = cli(
        capsys,
        "simulate",
        scenario_file(workdir, neighbours={"skin": 1e300}),
        "-o",
        workdir / "out.h5",
        "--progress",
        "none",
    )
    check_contract(res)


@pytest.mark.parametrize(
    "sections", [{"rods": {"tip_stiffness": 1e300}}, {"forces": {"uniform_field": {"B": [1e300, 0.0, 0.0]}}}]
)
def test_bug_overflowing_forces(sections, workdir, capsys):
    raw = copy.deepcopy(BASE)
    for k, v in sections.items():
        raw[k].update(v)
    scen = workdir / "s.toml"
    scen.write_text(to_toml(raw))
    res = cli(capsys, "simulate", scen, "-o", workdir / "out.h5", "--progress", "none")
    check_contract(res, allowed=(2, 3))


def test_bug_resume_into_an_unrelated_run(workdir, capsys, real_run):
    other = workdir / "B.h5"
    res = cli(
        capsys,
        "simulate",
        real_run["scenario"],
        "-o",
        other,
        "--progress",
        "none",
        "--set=rods.count=6",
        "--t-end=0.005",
    )
    assert res.code == 0
    before = other.read_bytes()
    ckpt = workdir / "A.checkpoint.h5"
    ckpt.write_bytes(real_run["checkpoint_bytes"])
    res = cli(capsys, "simulate", "--resume", ckpt, "-o", other, "--progress", "none", "--t-end=0.004")
    check_contract(res, allowed=(2,))
    assert other.read_bytes() == before


@pytest.mark.parametrize("content", ["empty", "foreign_non_ascii_group"])
def test_bug_failed_resume_rewrites_the_file(content, workdir, capsys, real_run):
    ckpt = workdir / "good.checkpoint.h5"
    ckpt.write_bytes(real_run["checkpoint_bytes"])
    target = workdir / "target.h5"
    if content == "empty":
        target.write_bytes(b"")
    else:
        with h5py.File(target, "w") as f:
            f.create_group("\u00e9t\u00e9")
    before = target.read_bytes()
    res = cli(capsys, "simulate", "--resume", ckpt, "-o", target, "--progress", "none")
    _expect_usage_error(res, "cannot resume")
    assert target.read_bytes() == before


def test_bug_resume_into_a_file_of_another_layout(workdir, capsys, real_run):
    ckpt = workdir / "good.checkpoint.h5"
    ckpt.write_bytes(real_run["checkpoint_bytes"])
    foreign = workdir / "foreign.h5"
    with h5py.File(foreign, "w") as f:
        f.create_group("particles/tips/position/step")
    before = foreign.read_bytes()
    res = cli(capsys, "simulate", "--resume", ckpt, "-o", foreign, "--progress", "none")
    check_contract(res, allowed=(2,))
    assert foreign.read_bytes() == before


@pytest.mark.parametrize("groups", [(), ("snapshot", "meta")])
def test_bug_checkpoint_with_missing_groups(groups, workdir, capsys):
    ckpt = workdir / "x.checkpoint.h5"
    with h5py.File(ckpt, "w") as f:
        f.attrs["format"] = CHECKPOINT_FORMAT
        for g in groups:
            f.create_group(g)
    _expect_usage_error(cli(capsys, "simulate", "--resume", ckpt), "cannot resume")


@pytest.mark.parametrize("layout", ["value_group", "value_only", "scalars"])
def test_bug_plot_foreign_file_with_run_layout(layout, workdir, capsys):
    path = workdir / "f.h5"
    with h5py.File(path, "w") as f:
        if layout == "value_group":
            f.create_group("parameters/selfas_graph")
            f.create_group("particles/tips/position/value")
        elif layout == "value_only":
            f.create_group("parameters/selfas_graph")
            f["particles/tips/position/value"] = np.zeros((2, 8, 3))
        else:
            f["parameters/selfas_graph"] = 1
            f["particles/tips/position/value"] = 1
    res = cli(capsys, "plot", path, "-o", workdir / "f.png")
    check_contract(res, allowed=(2,))


def test_bug_topology_foreign_graph(workdir, capsys):
    path = workdir / "f.h5"
    with h5py.File(path, "w") as f:
        f.create_group("parameters/selfas_graph")
        f["particles/tips/position/value"] = np.zeros((1, 8, 3))
        f["graph/step"] = np.zeros(1, dtype=np.int64)
    check_contract(cli(capsys, "topology", path), allowed=(2,))


@pytest.mark.parametrize("dpi", ["0", "-5", "1", "100000"])
def test_bug_plot_dpi(dpi, workdir, capsys, real_run):
    res = cli(capsys, "plot", real_run["run"], "-o", workdir / "f.png", f"--dpi={dpi}")
    _expect_usage_error(res, "--dpi")
    assert not (workdir / "f.png").exists()


@pytest.mark.parametrize("kind", ["density", "field", "flux"])
def test_bug_plot_infinite_r_max(kind, workdir, capsys, real_run):
    res = cli(capsys, "plot", real_run["run"], "--kind", kind, "-o", workdir / "f.png", "--r-max=inf")
    _expect_usage_error(res, "--r-max")


@pytest.mark.parametrize("kind", ["field", "flux"])
def test_bug_plot_huge_r_max_is_bounded(kind, workdir, capsys, real_run):
    """--r-max 1e9 set the default azimuthal sampling to ~2e11 points per radius (minutes or
    memory exhaustion); radii are bounded like every size-like option."""
    res = cli(capsys, "plot", real_run["run"], "--kind", kind, "-o", workdir / "f.png", "--r-max=1e9")
    _expect_usage_error(res, "at most 500 L")


@pytest.mark.parametrize("kind, plane", [("field", "nan"), ("flux", "inf")])
def test_bug_plot_nonfinite_planes(kind, plane, workdir, capsys, real_run):
    res = cli(capsys, "plot", real_run["run"], "--kind", kind, "-o", workdir / "f.png", "--planes", plane)
    _expect_usage_error(res, "--planes")


@pytest.mark.parametrize("data", ["truncated", "signature_junk"])
def test_bug_truncated_file_message_blames_file_locking(data, workdir, capsys, real_run):
    path = workdir / "run.h5"
    if data == "truncated":
        path.write_bytes(real_run["run_bytes"][: len(real_run["run_bytes"]) // 2])
    else:
        path.write_bytes(b"\x89HDF\r\n\x1a\n" + b"\xff" * 1024)  # HDF5: "bad superblock version number"
    res = cli(capsys, "topology", path)
    check_contract(res, allowed=(2,))
    assert "HDF5_USE_FILE_LOCKING" not in res.err and "still writing" not in res.err


@pytest.mark.parametrize("victim", ["other_file", "the_scenario"])
def test_bug_checkpoint_overwrites_an_existing_file(victim, workdir, capsys):
    if victim == "other_file":
        scen = scenario_file(workdir)
        precious = workdir / "new.checkpoint.h5"
        precious.write_bytes(b"results of last week")
    else:
        precious = workdir / "new.checkpoint.h5"
        precious.write_text(BASE_TEXT)
        scen = precious
    before = precious.read_bytes()
    res = cli(capsys, "simulate", scen, "-o", workdir / "new.h5", "--progress", "none")
    check_contract(res, allowed=(0, 2))
    assert precious.read_bytes() == before


def test_bug_resume_t_end_before_the_checkpoint(workdir, capsys, real_run):
    run = workdir / "run.h5"
    run.write_bytes(real_run["run_bytes"])
    ckpt = workdir / "run.checkpoint.h5"
    ckpt.write_bytes(real_run["checkpoint_bytes"])
    res = cli(capsys, "simulate", "--resume", ckpt, "-o", run, "--t-end=0.001", "--progress", "none")
    _expect_usage_error(res, "t_end")
    assert run.read_bytes() == real_run["run_bytes"]


@pytest.mark.parametrize(
    "rods", [{"electric_charge": {"distribution": "constant", "value": 0.0}}, {"magnetic_charge": {"value": 0.0}}]
)
def test_bug_yukawa_with_zero_charges(rods, workdir, capsys):
    out = workdir / "out.h5"
    res = cli(capsys, "simulate", scenario_file(workdir, rods=rods), "-o", out, "--progress", "none")
    check_contract(res, allowed=(0,))


@pytest.mark.parametrize(
    "args",
    [
        ["-o", ".", "--dry-run"],
        ["-o", "/", "--dry-run"],
        ["-o", "."],
        ['--set=output.file="."', "--dry-run"],
        ["--resume", "."],
        ["--resume", "/"],
    ],
)
def test_bug_output_path_without_a_name(args, workdir, capsys):
    scen = scenario_file(workdir)
    argv = ["simulate", *([] if "--resume" in args else [scen]), *args]
    check_contract(cli(capsys, *argv), allowed=(2,))


def test_bug_output_file_with_a_nul_character(workdir, capsys):
    precious = workdir / "a"
    precious.write_bytes(b"results of last week")
    scen = workdir / "s.toml"
    scen.write_text(BASE_TEXT + 'file = "a\\u0000b.h5"\n')
    res = cli(capsys, "simulate", scen.name, "--progress", "none")
    check_contract(res, allowed=(2,))
    assert precious.read_bytes() == b"results of last week"


@pytest.mark.parametrize("where", ["file_array", "file_table", "set_value"])
def test_bug_deeply_nested_toml(where, workdir, capsys):
    depth = 5000
    scen = workdir / "s.toml"
    if where == "file_array":
        scen.write_text("x = " + "[" * depth + "]" * depth + "\n")
    elif where == "file_table":
        scen.write_text("x = " + "{a = " * depth + "1" + "}" * depth + "\n")
    else:
        scen.write_text(BASE_TEXT)
    extra = [f"--set=rods.count={'[' * depth}{']' * depth}"] if where == "set_value" else []
    check_contract(cli(capsys, "simulate", scen, "--dry-run", *extra), allowed=(2,))


@pytest.mark.parametrize("value", ["1e10", "1e30"])
def test_bug_failure_file_holds_the_nan_of_the_failed_step(value, workdir, capsys):
    """Charges of 1e10 blow the scene up at step 1 (exit 3, the term named). The failure file held
    the failed step's NaN velocities; now it holds the last finite state (the run's start here,
    verified and resumable) and the failed step's values with the non-finite entries coded apart."""
    from selfas_graph.io.checkpoint import read_checkpoint

    out = workdir / "out.h5"
    res = cli(
        capsys,
        "simulate",
        scenario_file(workdir),
        "-o",
        out,
        "--progress",
        "none",
        f"--set=rods.magnetic_charge.value={value}",
    )
    check_contract(res, allowed=(3,))
    failure = workdir / "out.failure.h5"
    for path in sorted(workdir.glob("*.h5")):
        assert non_finite_datasets(path) == [], path.name
    snap, meta = read_checkpoint(failure)  # refuses a non-finite snapshot
    assert int(snap["step"]) == 0 and "numerical failure at step 1" in meta["failure"]
    with h5py.File(failure, "r") as f:
        failed = f["failed"]
        assert failed.attrs["step"] == 1
        code = failed["nonfinite/velocity"][()]
        assert code.shape == failed["velocity"].shape == (8, 3) and code.any()
        assert set(np.unique(code)) <= {0, 1, 2, 3}  # finite, NaN, +inf, -inf
        assert np.all(failed["velocity"][()][code != 0] == 0.0)
        assert np.isfinite(failed["velocity"].attrs["largest_finite"])


@pytest.mark.parametrize("command", ["simulate", "plot", "export", "ensemble"])
def test_bug_a_dangling_symbolic_link_as_the_output(command, workdir, capsys, real_run):
    """``-o dang.h5`` where dang.h5 is a symbolic link into a folder that does not exist: simulate
    removed the link after its failed write, plot and export replaced it by a regular file (ensemble,
    given it as its folder, said only "File exists"). Now every command refuses it (exit 2, naming the link and where it points) and leaves it as it was."""
    link = workdir / "dang.h5"
    link.symlink_to(workdir / "nowhere" / "x.h5")
    args = {
        "simulate": ["simulate", scenario_file(workdir), "--progress", "none"],
        "plot": ["plot", real_run["run"]],
        "export": ["export", real_run["run"], "--format", "xyz"],
        "ensemble": ["ensemble", scenario_file(workdir), "--seeds", "1"],
    }[command]
    before = tree(workdir)
    res = cli(capsys, *args, "-o", link)
    _expect_usage_error(res, "dang.h5", "symbolic link")
    assert tree(workdir) == before
    assert link.is_symlink() and os.readlink(link) == str(workdir / "nowhere" / "x.h5")


@pytest.mark.parametrize("option", ["-o", "--json", "--plot=", "--output="])
def test_bug_bench_tools_leave_a_dangling_link_as_it_is(tmp_path, capsys, option):
    """`selfas-graph bench NAME -o LINK` with LINK a symbolic link to nothing: exit 2 naming the link,
    nothing run, the link unchanged (as simulate, plot, export and ensemble do)."""
    from pathlib import Path

    from selfas_graph.cli.main import main

    quick = Path(__file__).resolve().parents[2] / "scenarios" / "quick.toml"
    link = tmp_path / "dang.json"
    os.symlink(tmp_path / "missing" / "x.json", link)
    args = [option + str(link)] if option.endswith("=") else [option, str(link)]
    code = main(["bench", "percolation", str(quick), "--counts", "10", "--seeds", "1"] + args)
    assert code == 2 and "symbolic link" in capsys.readouterr().err
    assert os.readlink(link) == str(tmp_path / "missing" / "x.json") and sorted(os.listdir(tmp_path)) == ["dang.json"]


@pytest.mark.parametrize("command", ["topology", "analyze", "plot", "export", "compare"])
def test_bug_a_run_file_damaged_inside_gives_a_traceback(command, workdir, capsys, real_run):
    """Each B-tree node of the run file in turn made unreadable (its signature overwritten, as bytes
    written over the file's metadata do): HDF5 says so only when the part is read, from inside h5py."""
    data = real_run["run_bytes"]
    nodes = [k for k in range(len(data) - 4) if data[k : k + 4] == b"TREE"]
    assert len(nodes) > 5
    args = {
        "topology": (),
        "analyze": ("--series",),
        "plot": ("--kind", "timeline", "-o", workdir / "t.png", "--force"),
        "export": ("--format", "xyz", "-o", workdir / "t.xyz", "--force"),
        "compare": (),
    }[command]
    damaged = 0
    for k in nodes:
        path = workdir / "damaged.h5"
        path.write_bytes(data[:k] + b"XXXX" + data[k + 4 :])
        res = cli(capsys, command, *((real_run["run"], path) if command == "compare" else (path,)), *args)
        check_contract(res, allowed=(0, 1, 2))
        if res.code == 2:
            damaged += 1
            assert "damaged" in res.err or "cannot" in res.err, res.err
    assert damaged > 0


@pytest.mark.parametrize("command", ["resume", "ensemble"])
def test_bug_a_damaged_run_file_to_continue_gives_a_traceback(command, workdir, capsys, real_run):
    """`simulate --resume` and an ensemble's plan and summary (`ensemble --no-run`, which plans every seed
    and summarises the files) read a run file whose B-tree node was made unreadable: exit 2 naming the
    damage (resume) or the seed left out of the summary and named, never HDF5's traceback."""
    import shutil

    data = real_run["run_bytes"]
    nodes = [k for k in range(len(data) - 4) if data[k : k + 4] == b"TREE"]
    assert len(nodes) > 5
    refused = 0
    for k in nodes:
        folder = workdir / f"node{k}"
        folder.mkdir()
        run = folder / ("run.h5" if command == "resume" else "seed_0007.h5")
        run.write_bytes(data[:k] + b"XXXX" + data[k + 4 :])
        shutil.copy(real_run["checkpoint"], checkpoint_path(run))
        if command == "resume":
            res = cli(capsys, "simulate", "--resume", run, "--t-end", "0.003", "--progress", "none")
            check_contract(res, allowed=(0, 2))
        else:
            res = cli(capsys, "ensemble", real_run["scenario"], "--seeds", "1", "-o", folder, "--no-run")
            check_contract(res, allowed=(0, 2))
        if "a damaged file?" in res.err or "a damaged file?" in res.out:
            refused += 1
    assert refused > 0


def test_bug_hdf5_failing_on_damaged_metadata_in_a_run_gives_a_traceback(workdir, capsys, real_run, monkeypatch):
    """HDF5 failing in the middle of a run on a file's damaged metadata (a RuntimeError raised in h5py, no
    errno) ends the run as a failed write does: exit 4 with the I/O error message, the file kept readable."""
    from selfas_graph.io.run_writer import RunWriter

    data = real_run["run_bytes"]
    k = [k for k in range(len(data) - 4) if data[k : k + 4] == b"TREE"][0]
    damaged = workdir / "damaged.h5"
    damaged.write_bytes(data[:k] + b"XXXX" + data[k + 4 :])
    calls = []
    original = RunWriter.reserve

    def reserve(self):
        calls.append(1)
        if len(calls) > 1:  # the second frame: HDF5 fails on the damaged node, from inside h5py
            with h5py.File(damaged, "r") as f:
                f.visititems(lambda name, obj: dict(obj.attrs))
        return original(self)

    monkeypatch.setattr(RunWriter, "reserve", reserve)
    res = cli(capsys, "simulate", real_run["scenario"], "-o", workdir / "out.h5", "--progress", "none")
    assert res.code == 4 and "Traceback" not in res.err, res.err
    assert "I/O error at step" in res.err and "--resume" in res.err
    from selfas_graph.io.h5md import RunFile

    with RunFile(workdir / "out.h5") as run:
        assert run.n_frames >= 1 and np.isfinite(run.position(-1)).all()


@pytest.mark.parametrize("victim", ["run", "checkpoint"])
@pytest.mark.parametrize("name", ["victim.checkpoint.h5", "victim.png", "victim.gif"])
def test_bug_plot_force_writes_over_an_hdf5_file(victim, name, workdir, capsys, real_run):
    """`plot -o RUN.checkpoint.h5 --force` wrote a PNG over the checkpoint; an HDF5 file is never replaced,
    whatever its name says."""
    target = workdir / name
    target.write_bytes(real_run["run_bytes"] if victim == "run" else real_run["checkpoint_bytes"])
    before = target.read_bytes()
    more = ("--movie", target) if name.endswith(".gif") else ("--kind", "timeline", "-o", target)
    res = cli(capsys, "plot", real_run["run"], *more, "--force")
    _expect_usage_error(res, "is an HDF5 file")
    assert target.read_bytes() == before


@pytest.mark.parametrize(
    "suffix, magic", [(".pdf", b"%PDF"), (".svg", b"<?xml"), (".png", b"\x89PNG"), ("", b"\x89PNG")]
)
def test_bug_plot_writes_png_bytes_under_any_name(suffix, magic, workdir, capsys, real_run):
    out = workdir / f"t{suffix}"
    check_contract(cli(capsys, "plot", real_run["run"], "--kind", "timeline", "-o", out), allowed=(0,))
    assert out.read_bytes().startswith(magic)


def test_bug_plot_to_a_suffix_it_cannot_write(workdir, capsys, real_run):
    _expect_usage_error(
        cli(capsys, "plot", real_run["run"], "--kind", "timeline", "-o", workdir / "t.txt"), ".png, .pdf or .svg"
    )
    assert not (workdir / "t.txt").exists()


@pytest.mark.parametrize(
    "argv, words",
    [
        (("analyze", "RUN", "--every", "5"), ("--every 5", "--series")),
        (("topology", "RUN", "--events", "-1"), ("--events -1", ">= 0")),
    ],
)
def test_bug_an_option_that_does_nothing_is_taken_without_a_word(argv, words, workdir, capsys, real_run):
    res = cli(capsys, *(real_run["run"] if a == "RUN" else a for a in argv))
    _expect_usage_error(res, *words)
