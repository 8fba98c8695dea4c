"""Files written whole or not at all (selfas_graph/io/atomic.py), and one rule through a symbolic link:
the file the link names is replaced, not the link (export and plot replaced the link, while the movie
and the results page wrote through it)."""

import os
from pathlib import Path

import pytest

from selfas_graph.io.atomic import atomic_write, default_mode, write_text_atomic


def test_a_write_through_a_link_replaces_the_file_it_names(tmp_path):
    target = tmp_path / "target.json"
    target.write_text("old")
    link = tmp_path / "link.json"
    link.symlink_to(target)
    assert write_text_atomic(link, "new") == target.resolve()
    assert link.is_symlink() and target.read_text() == "new"


def test_a_failed_write_leaves_the_file_there_was_and_no_temporary_file(tmp_path):
    path = tmp_path / "summary.csv"
    path.write_text("the summary there was")

    def fail(tmp):
        Path(tmp).write_text("half of it")
        raise OSError(28, "No space left on device")

    with pytest.raises(OSError, match="No space"):
        atomic_write(path, fail)
    assert path.read_text() == "the summary there was"
    assert [p.name for p in tmp_path.iterdir()] == ["summary.csv"]


def test_a_new_file_gets_the_permissions_open_would_give(tmp_path):
    path = write_text_atomic(tmp_path / "a.txt", "x")
    assert os.stat(path).st_mode & 0o777 == default_mode()


def test_export_and_plot_write_through_a_link_as_the_movie_and_the_page_do(tmp_path, real_run):
    """``export -o link.xyz --force`` and ``plot -o link.png --force`` made the link a file of their own."""
    from selfas_graph.cli.main import main

    for name, argv in (
        ("xyz", ["export", str(real_run["run"]), "--format", "xyz"]),
        ("png", ["plot", str(real_run["run"])]),
    ):
        target = tmp_path / f"target.{name}"
        target.write_bytes(b"")
        link = tmp_path / f"link.{name}"
        link.symlink_to(target)
        assert main([*argv, "-o", str(link), "--force"]) == 0
        assert link.is_symlink() and target.stat().st_size > 0
