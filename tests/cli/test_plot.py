"""``selfas-graph plot``: every kind writes a PNG, files are protected, errors are one line (exit 2).

One small run of ``scenarios/quick.toml`` up to t = 2.5 (past its short circuit at
t = 2.01, so there are filaments, dead ends and currents) is made once for the module.
"""

import sys
from pathlib import Path

import pytest

pytest.importorskip("matplotlib")

from selfas_graph.cli.main import main  # noqa: E402

REPO = Path(__file__).resolve().parents[2]
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def run_file(tmp_path_factory):
    out = tmp_path_factory.mktemp("plot") / "quick.h5"
    rc = main(
        ["simulate", str(REPO / "scenarios" / "quick.toml"), "-o", str(out), "--t-end", "2.5", "--progress", "none"]
    )
    assert rc == 0
    return out


@pytest.fixture(scope="module")
def no_graph_run(tmp_path_factory):
    """A run without contacts: positions only, no graph data (a few steps)."""
    out = tmp_path_factory.mktemp("plot_nograph") / "nograph.h5"
    rc = main(
        [
            "simulate",
            str(REPO / "scenarios" / "quick.toml"),
            "-o",
            str(out),
            "--t-end",
            "0.01",
            "--progress",
            "none",
            "--set",
            "contacts.enabled=false",
            "--set",
            "circuit=false",
            "--set",
            "forces.current_field=false",
            "--set",
            "forces.current_lorentz=false",
        ]
    )
    assert rc == 0
    return out


def is_png(path):
    data = Path(path).read_bytes()
    return data[:8] == PNG_SIGNATURE and len(data) > 1000


@pytest.mark.parametrize("kind", ["snapshot", "density", "field", "flux", "timeline", "moment", "fractal", "skeleton"])
def test_every_kind_writes_a_png(run_file, tmp_path, kind, capsys):
    """Each figure kind of the paper (docs/model.md 'Figure diagnostics') renders headless to a non-empty PNG."""
    out = tmp_path / f"{kind}.png"
    assert main(["plot", str(run_file), "--kind", kind, "-o", str(out)]) == 0
    assert is_png(out)
    assert str(out) in capsys.readouterr().out


def test_large_run_snapshot_colours_the_largest_structure(run_file, tmp_path, monkeypatch, capsys):
    """Above LARGE_RUN rods the snapshot colours the largest structure red (paper Fig. 6); the
    threshold is lowered here so that the 300-rod run takes that branch."""
    from selfas_graph.cli.plots import frame  # where the snapshot reads LARGE_RUN

    monkeypatch.setattr(frame, "LARGE_RUN", 100)
    out = tmp_path / "large.png"
    assert main(["plot", str(run_file), "--kind", "snapshot", "-o", str(out)]) == 0
    assert is_png(out)


def test_options_planes_time_and_dipole_units(run_file, tmp_path):
    """--planes, --time, --n-phi and --z-mext are accepted and still give PNGs."""
    out = tmp_path / "flux.png"
    assert (
        main(
            [
                "plot",
                str(run_file),
                "--kind",
                "flux",
                "--time",
                "1.6",
                "--planes",
                "-1",
                "1",
                "--n-phi",
                "128",
                "--z-mext",
                "10",
                "-o",
                str(out),
            ]
        )
        == 0
    )
    assert is_png(out)


def test_default_name_and_no_overwrite_without_force(run_file, capsys):
    """The default output is RUN_kind_frameK.png next to the run (K the resolved frame index, here
    frame -5 -> 1 of 0..5); an existing file is kept unless --force."""
    out = run_file.with_name(f"{run_file.stem}_density_frame1.png")
    assert main(["plot", str(run_file), "--kind", "density", "--frame", "-5"]) == 0
    assert is_png(out)
    before = out.read_bytes()
    out.write_bytes(b"keep me")
    capsys.readouterr()
    assert main(["plot", str(run_file), "--kind", "density", "--frame", "1"]) == 2
    err = capsys.readouterr().err
    assert "exists" in err and "--force" in err and len(err.strip().splitlines()) == 1
    assert out.read_bytes() == b"keep me"
    assert main(["plot", str(run_file), "--kind", "density", "--frame", "1", "--force"]) == 0
    assert out.read_bytes() == before


def test_an_existing_file_of_a_suffix_no_figure_takes_is_refused_for_its_suffix(run_file, tmp_path, capsys):
    """An existing file whose suffix is not a figure's: the error names the suffix, not --force (which
    would then be refused for the suffix), and the file is kept."""
    out = tmp_path / "frames.gsd"
    out.write_bytes(b"keep me")
    for extra in ([], ["--force"]):
        assert main(["plot", str(run_file), "--kind", "density", "-o", str(out), *extra]) == 2
        err = capsys.readouterr().err
        assert "gsd" in err and "--force" not in err, err
    assert out.read_bytes() == b"keep me"


def test_dpi_is_refused_for_a_vector_figure(run_file, tmp_path, capsys):
    """A PDF or SVG is drawn in vectors (no figure rasterises a part): --dpi would be ignored, so it is
    refused by name, as every option a figure does not use."""
    for suffix in (".svg", ".pdf"):
        out = tmp_path / f"d{suffix}"
        assert main(["plot", str(run_file), "--kind", "density", "-o", str(out), "--dpi", "300"]) == 2
        assert "--dpi" in capsys.readouterr().err and not out.exists()
    assert main(["plot", str(run_file), "--kind", "density", "-o", str(tmp_path / "d.png"), "--dpi", "50"]) == 0


def test_missing_file_is_a_clear_error(tmp_path, capsys):
    """A run file that does not exist: exit 2, one line naming the file."""
    missing = tmp_path / "nothere.h5"
    assert main(["plot", str(missing), "--kind", "snapshot"]) == 2
    err = capsys.readouterr().err
    assert "no such file" in err and str(missing) in err and len(err.strip().splitlines()) == 1


def test_not_a_run_file_is_a_clear_error(tmp_path, capsys):
    """A file that is not HDF5: exit 2 with the reader's explanation."""
    bad = tmp_path / "bad.h5"
    bad.write_text("not hdf5")
    assert main(["plot", str(bad)]) == 2
    assert "not a readable HDF5 file" in capsys.readouterr().err


def test_frame_out_of_range_is_a_clear_error(run_file, tmp_path, capsys):
    """--frame beyond the saved frames (0..5): exit 2, the valid range in the message, nothing written."""
    out = tmp_path / "x.png"
    assert main(["plot", str(run_file), "--kind", "field", "--frame", "99", "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert "frame 99 out of range" in err and "0..5" in err
    assert not out.exists()


def test_kinds_that_need_the_graph_say_so(no_graph_run, tmp_path, capsys):
    """Without graph data, field, flux and timeline fail with exit 2 and the reason; snapshot and
    density still draw (all rods grey / total density only)."""
    for kind in ("field", "flux", "timeline", "moment", "fractal", "skeleton"):
        assert main(["plot", str(no_graph_run), "--kind", kind, "-o", str(tmp_path / f"{kind}.png")]) == 2
        assert "no graph data" in capsys.readouterr().err
    for kind in ("snapshot", "density"):
        out = tmp_path / f"{kind}.png"
        assert main(["plot", str(no_graph_run), "--kind", kind, "-o", str(out)]) == 0
        assert is_png(out)


def test_missing_matplotlib_names_the_extra(run_file, tmp_path, monkeypatch, capsys):
    """Without matplotlib the command says which extra to install (exit 2)."""
    monkeypatch.setitem(sys.modules, "matplotlib", None)  # makes `import matplotlib` raise ImportError
    assert main(["plot", str(run_file), "-o", str(tmp_path / "x.png")]) == 2
    assert 'pip install "selfas-graph[plot]"' in capsys.readouterr().err


def test_ensemble_summary_plot_draws_every_measure_with_its_band(tmp_path):
    """A hand-made summary of two measures at three times, the last with one seed left."""
    from selfas_graph.cli.main import CliError
    from selfas_graph.cli.plot import plot_summary

    summary = {
        "n_seeds": 3,
        "times": [0.0, 1.0, 2.0],
        "measures": {
            "filament_rods": {"unit": "rods", "mean": [0.0, 10.0, 12.0], "sem": [0.0, 1.5, None], "n": [3, 3, 1]},
            "cycle_rank": {"unit": "loops", "mean": [0.0, None, 4.0], "sem": [0.0, None, None], "n": [3, 3, 1]},
        },
    }
    out = plot_summary(summary, tmp_path / "s.png", title="test")
    assert is_png(out)
    with pytest.raises(CliError, match="none of the measures"):
        plot_summary(summary, tmp_path / "t.png", title="test", measures=["no_such_measure"])


@pytest.mark.parametrize("suffix", [".gif", ".mp4"])
def test_movie_renders_every_frame(run_file, tmp_path, suffix, capsys):
    """``--movie OUT.gif|mp4``: one snapshot per saved frame (6 frames to t = 2.5 at interval 0.5),
    no partial file left beside it; an existing movie is kept without --force."""
    if suffix == ".mp4":
        pytest.importorskip("imageio_ffmpeg")
    out = tmp_path / f"quick{suffix}"
    assert main(["plot", str(run_file), "--movie", str(out)]) == 0
    assert "(6 frames" in capsys.readouterr().out
    head = out.read_bytes()[:12]
    assert head.startswith(b"GIF89a") if suffix == ".gif" else head[4:8] == b"ftyp"
    assert sorted(p.name for p in tmp_path.iterdir()) == [out.name]
    if suffix == ".gif":
        from PIL import Image

        assert Image.open(out).n_frames == 6
    capsys.readouterr()
    assert main(["plot", str(run_file), "--movie", str(out)]) == 2
    assert "pass --force to overwrite it or --movie to choose another name" in capsys.readouterr().err  # not -o


@pytest.mark.parametrize(
    "figure, option, used_by",
    [
        (["--kind", "density"], ["--every", "3"], "--kind moment, fractal or skeleton and by --movie"),
        (["--kind", "timeline"], ["--frame", "3"], "--kind snapshot, density, field or flux"),
        (["--kind", "moment"], ["--time", "1"], "--kind snapshot, density, field or flux"),
        (["--kind", "snapshot"], ["--bins", "10"], "--kind density,"),
        (["--kind", "timeline"], ["--r-max", "3"], "--kind density, field or flux"),
        (["--kind", "density"], ["--planes", "0"], "--kind field or flux"),
        (["--kind", "density"], ["--n-phi", "64"], "--kind field or flux"),
        (["--kind", "field"], ["--z-mext", "2"], "--kind flux,"),
        (["--movie", "m.gif"], ["--frame", "1"], "--kind snapshot, density, field or flux"),
    ],
)
def test_an_option_the_figure_does_not_use_is_refused(run_file, tmp_path, capsys, figure, option, used_by):
    """An option that shapes other figures only is refused by name (it was ignored without a word),
    as ``analyze --every`` without a series is; nothing is drawn."""
    figure = [str(tmp_path / w) if w.endswith(".gif") else w for w in figure]
    out = [] if "--movie" in figure else ["-o", str(tmp_path / "x.png")]
    assert main(["plot", str(run_file), *figure, *option, *out]) == 2
    err = capsys.readouterr().err
    assert f"error: {option[0]} is used by {used_by}" in err and "leave it out" in err
    assert not any(tmp_path.iterdir())


def test_a_movie_refuses_o(run_file, tmp_path, capsys):
    """A movie is written to its --movie name: -o beside it was ignored."""
    assert main(["plot", str(run_file), "--movie", str(tmp_path / "m.gif"), "-o", str(tmp_path / "o.gif")]) == 2
    assert "a movie is written to its --movie name" in capsys.readouterr().err
    assert not any(tmp_path.iterdir())


def test_movie_refuses_other_formats_and_kinds(run_file, tmp_path, capsys):
    assert main(["plot", str(run_file), "--movie", str(tmp_path / "m.avi")]) == 2
    assert ".gif or .mp4" in capsys.readouterr().err
    assert main(["plot", str(run_file), "--movie", str(tmp_path / "m.gif"), "--kind", "density"]) == 2
    assert not any(tmp_path.iterdir())


@pytest.mark.parametrize("movie", [False, True])
def test_a_folder_that_is_missing_or_not_writable_is_a_usage_error(run_file, tmp_path, monkeypatch, movie, capsys):
    """Refused before drawing, exit 2 as in simulate: found only when saving, it was an I/O error (exit 4).
    The folder's permissions are stood in for by os.access, which a root user's tests cannot see denied."""
    name = "out.gif" if movie else "out.png"
    option = "--movie" if movie else "-o"
    assert main(["plot", str(run_file), option, str(tmp_path / "none" / name)]) == 2
    assert "does not exist" in capsys.readouterr().err
    monkeypatch.setattr("selfas_graph.cli.paths.os.access", lambda path, mode: False)
    assert main(["plot", str(run_file), option, str(tmp_path / name)]) == 2
    assert f"the folder {tmp_path} of the" in capsys.readouterr().err
    assert not (tmp_path / name).exists()


@pytest.mark.parametrize("r_max", [None, 3.0])
def test_density_counts_every_rod_it_says_it_counts(run_file, tmp_path, monkeypatch, r_max):
    """The default outer radius is the farthest rod's distance from the axis, and the shells are
    half-open: that rod was left out, while the legend said every rod was counted."""
    import numpy as np

    import selfas_graph.cli.plot as plot_cli
    from selfas_graph.analysis import rod_centres
    from selfas_graph.io.h5md import RunFile

    figures = []
    monkeypatch.setattr(plot_cli, "_save_png", lambda fig, out, dpi: figures.append(fig))
    more = [] if r_max is None else ["--r-max", str(r_max)]
    assert main(["plot", str(run_file), "--kind", "density", "-o", str(tmp_path / "d.png"), *more]) == 0
    with RunFile(run_file) as run:
        centre, gap = rod_centres(run.position(-1)), float(run.parameters["forces"]["electrodes"]["gap"])
    rho = np.hypot(centre[:, 0], centre[:, 1])
    within = len(rho) if r_max is None else int((rho < r_max).sum())
    total = figures[0].axes[0].lines[0]
    r = total.get_xdata()
    width = r[1] - r[0]
    shells = np.pi * ((r + width / 2) ** 2 - (r - width / 2) ** 2) * gap
    assert np.rint(np.sum(total.get_ydata() * shells)) == within
    label = f"total ({len(rho)} rods)" if within == len(rho) else f"total ({within} of {len(rho)} rods within r_max)"
    assert total.get_label() == label


def _copy_torn(run_file, tmp_path, group_rows):
    """A copy of the run whose datasets under each group of ``group_rows`` (name: rows kept) a kill cut
    short: the last frame's graph record or observables rows missing."""
    import shutil

    import h5py

    out = tmp_path / "torn.h5"
    shutil.copy(run_file, out)
    with h5py.File(out, "r+") as f:
        for group, keep in group_rows.items():
            f[group].visititems(
                lambda name, o: o.resize(keep, axis=0) if isinstance(o, h5py.Dataset) and o.shape[0] == 6 else None
            )
    return out


def test_a_frame_whose_graph_record_a_kill_tore_leaves_the_plots_over_time_drawing(run_file, tmp_path, capsys):
    """The last of the 6 frames without its graph record: the plots over the frames draw (that frame
    has no graph, a gap), a plot of that frame alone says it has none, and ``topology`` numbers the
    frames as every other command does (frame 4 of 0..5), not by graph records."""
    import json

    torn = _copy_torn(run_file, tmp_path, {"graph": 5})
    for kind in ("timeline", "moment"):
        assert main(["plot", str(torn), "--kind", kind, "-o", str(tmp_path / f"{kind}.png")]) == 0
    assert main(["plot", str(torn), "--kind", "field", "-o", str(tmp_path / "f.png")]) == 2
    assert "no graph data saved at frame 5" in capsys.readouterr().err
    assert main(["topology", str(torn), "--frame", "4"]) == 0
    assert "frame 4 of 0..5" in capsys.readouterr().out
    assert main(["topology", str(torn)]) == 2
    assert "no graph data saved at frame 5" in capsys.readouterr().err
    assert main(["topology", str(run_file), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["total_current"] is not None


def test_topology_gives_no_current_of_another_frame_where_the_frames_row_is_missing(run_file, tmp_path, capsys):
    """The last frame's observables a row short: its total current is unknown (null), not the frame
    before's."""
    import json

    torn = _copy_torn(run_file, tmp_path, {"observables": 5})
    assert main(["topology", str(torn), "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["frame"] == 5 and data["total_current"] is None and data["effective_resistance"] is None


def test_a_movie_of_a_file_without_frames_or_with_damaged_contents_is_a_clear_error(run_file, tmp_path, capsys):
    """As the PNG path says it (exit 2, one line), not with a traceback."""
    import shutil

    import h5py

    empty, bad = tmp_path / "empty.h5", tmp_path / "bad.h5"
    shutil.copy(run_file, empty)
    shutil.copy(run_file, bad)
    with h5py.File(empty, "r+") as f:
        for name in ("step", "time", "value"):
            f[f"particles/tips/position/{name}"].resize(0, axis=0)
    with h5py.File(bad, "r+") as f:
        f["parameters/selfas_graph"].attrs["parameters_json"] = "{"
    assert main(["plot", str(empty), "--movie", str(tmp_path / "e.gif")]) == 2
    assert "the run has no saved frames" in capsys.readouterr().err
    assert main(["plot", str(bad), "--movie", str(tmp_path / "b.gif")]) == 2
    assert "inconsistent run data" in capsys.readouterr().err
    assert not list(tmp_path.glob("*.gif"))


def test_a_movies_dpi_given_as_150_is_used(run_file, tmp_path):
    """--dpi 150 was taken for "not given" (a movie's default 80)."""
    from PIL import Image

    sizes = {}
    for dpi in ([], ["--dpi", "150"]):
        out = tmp_path / f"m{len(dpi)}.gif"
        assert main(["plot", str(run_file), "--movie", str(out), "--every", "5", *dpi]) == 0
        sizes[len(dpi)] = Image.open(out).size
    assert sizes[2][0] == pytest.approx(sizes[0][0] * 150 / 80, rel=0.02)


def test_the_plots_over_time_take_the_last_frame_with_every(monkeypatch):
    """--every 4 over 6 frames: frames 0, 4 and the last, 5."""
    from types import SimpleNamespace

    from selfas_graph.analysis import claims
    from selfas_graph.cli.plots import series

    seen = []
    monkeypatch.setattr(claims, "claims_series", lambda run, frames, loops: seen.append(list(frames)))
    series._series(SimpleNamespace(n_frames=6), SimpleNamespace(every=4))
    series._series(SimpleNamespace(n_frames=5), SimpleNamespace(every=4))
    assert seen == [[0, 4, 5], [0, 4]]


@pytest.mark.parametrize("movie", [False, True])
def test_a_full_disk_is_an_io_error_and_a_wrong_target_a_usage_error(run_file, tmp_path, monkeypatch, movie, capsys):
    """The rule of every command that writes (cli.main.write_failed): exit 4 where the system could not
    store the bytes, 2 where the user must name another target."""
    import errno

    name = "out.gif" if movie else "out.png"
    option = "--movie" if movie else "-o"
    where = "selfas_graph.cli.movie.atomic_write" if movie else "selfas_graph.cli.plots.style.atomic_write"
    for error, code in [
        (OSError(errno.ENOSPC, "No space left on device"), 4),
        (IsADirectoryError(21, "Is a directory"), 2),
    ]:

        def fail(path, write, error=error):
            raise error

        monkeypatch.setattr(where, fail)
        assert main(["plot", str(run_file), option, str(tmp_path / name)]) == code
        assert f"cannot write {tmp_path / name}: {error.strerror}" in capsys.readouterr().err
        assert not (tmp_path / name).exists()
