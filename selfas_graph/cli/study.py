"""The results page from runs of the shipped code: ``selfas-graph study list|run|summarise|page``.

``docs/studies.toml`` names each study (a scenario, overrides, seeds, end time, the times to
summarise) and each claim. ``study run NAME`` runs the study's seeds into ``RUNS/NAME/`` (the
``ensemble`` command with the study's arguments: resumable, locked, the same files; several
studies' seeds share one pool of ``--jobs`` workers, so no worker waits for the end of a study; a
seed file made by a version older than the studies file's ``trajectories_since``, or than the
study's own later one, is not reused: ``--force`` replaces it);
``study summarise NAME`` reads the run files and writes the study's small summary
``docs/results/NAME.json`` (per-seed values of every measure at every time, the short-circuit
episodes at event time, and the version, commit, CPU, threads and wall time of the runs) and its
figures into ``docs/figures/`` (``--figures``; by default ``figures/`` beside ``--page``); ``study page``
writes every generated table of docs/results.md from the summaries and draws the figures made from
them again, naming each file (``--check``: write nothing, exit 1 if the page differs from what the
summaries give). The paths of a studies file, and the defaults, are read from the working directory.
"""

from __future__ import annotations

import functools
import sys
from pathlib import Path

from ..provenance import older_version
from .ensemble import _positive_int
from .main import CliError, counted, interrupted_code, write_failed

DEFAULT_STUDIES = "docs/studies.toml"
DEFAULT_SUMMARIES = "docs/results"
#: the figures' folder, beside the results page that shows them (docs/figures for docs/results.md)
FIGURES_BESIDE_PAGE = "figures"
DEFAULT_PAGE = "docs/results.md"
#: the result file of a percolation study in its run folder
PERCOLATION_JSON = "percolation.json"
#: frames of a study's movie at most
MOVIE_FRAMES = 150


#: the options (argparse destinations) each action reads, besides --studies: another's given is refused
USED = {
    "list": set(),
    "run": {"runs", "jobs", "force", "names"},
    "summarise": {"runs", "summaries", "figures", "page", "no_figures", "no_movie", "names"},
    "page": {"summaries", "figures", "page", "check", "no_figures"},
}
_OPTIONS = sorted(set().union(*USED.values()) - {"names"})


def add_arguments(p):
    p.add_argument("action", choices=("list", "run", "summarise", "page"), help="what to do")
    p.add_argument("names", nargs="*", metavar="NAME", help="studies (run, summarise; default for summarise: all)")
    p.set_defaults(_rest="names")  # names after the options count too (cli/main.py::parse_args)
    p.add_argument("--studies", default=DEFAULT_STUDIES, help=f"the studies file (default {DEFAULT_STUDIES})")
    p.add_argument("--runs", default="runs", help="folder of the run files, one subfolder per study (default runs)")
    p.add_argument(
        "--jobs", type=_positive_int, default=1, help="run: seeds at once on this machine (as ensemble --jobs)"
    )
    p.add_argument("--force", action="store_true", help="run: replace seed files that cannot be reused")
    p.add_argument(
        "--summaries", default=DEFAULT_SUMMARIES, help=f"folder of the summaries (default {DEFAULT_SUMMARIES})"
    )
    p.add_argument(
        "--figures",
        default=None,
        help=f"folder of the figures (default: {FIGURES_BESIDE_PAGE}/ beside the --page, {DEFAULT_PAGE})",
    )
    p.add_argument("--page", default=DEFAULT_PAGE, help=f"the results page (default {DEFAULT_PAGE})")
    p.add_argument("--check", action="store_true", help="page: write nothing; exit 1 if the page is not up to date")
    p.add_argument("--no-figures", action="store_true", help="summarise: the summary only; page: the page only")
    p.add_argument("--no-movie", action="store_true", help="summarise: no movie of the first seed")
    p.set_defaults(_defaults={d: p.get_default(d) for d in _OPTIONS})  # what _check_options compares with


def _studies(args):
    from ..studies import StudiesError, load_studies

    try:
        return load_studies(args.studies)
    except StudiesError as exc:
        hint = ""
        if not Path(args.studies).exists():
            hint = (
                f"; the default paths are read from the working directory, {Path.cwd()}: run the command from "
                "the repository's root, or name the studies file with --studies"
            )
        raise CliError(f"{exc}{hint}") from None


def _pick(studies, names):
    from ..studies import StudiesError

    try:
        return [studies.study(n) for n in names] if names else list(studies.studies.values())
    except StudiesError as exc:
        raise CliError(str(exc)) from None


def _percolation_version(path) -> str:
    """The version that wrote a percolation result file ("unknown" when it cannot be read)."""
    import json

    try:
        return str(json.loads(Path(path).read_text(encoding="utf-8")).get("version") or "unknown")
    except (OSError, ValueError, AttributeError):
        return "unknown"


def _run_together(picked, args, older_than=""):
    """``study run A B ...``: the seeds of the ensemble studies ``picked`` in one pool of ``--jobs``
    workers (local processes or the ranks of ``mpiexec``), each study's folder locked throughout;
    then each folder's ensemble summary, as ``selfas-graph ensemble`` writes it. The exit code, as the
    ``ensemble`` command's (4 when a seed could not write, with no summary; 3 for failed seeds, also
    those kept from before), or None on an MPI worker rank."""
    import sys
    import time

    from ..ensemble import EnsembleError, write_summary
    from ..parallel import task_pool
    from ..studies import run_studies
    from .ensemble import SeedReport, pool_text
    from .main import EXIT_NUMERICAL, CliIOError

    kept_failed = []
    with task_pool(args.jobs) as pool:
        if pool.is_worker:
            return None  # an MPI rank that ran seeds for rank 0
        where = pool_text(pool)
        report = SeedReport(folders=True)

        def announce(planned):  # each study's plan, before the first seed starts
            for ens, plan in planned:
                count = {a: sum(p.action == a for p in plan) for a in ("run", "resume", "done", "failed")}
                report.total += count["run"] + count["resume"]
                print(
                    f"study {ens.folder.name}: seeds {ens.seeds[0]}..{ens.seeds[-1]} to t = {ens.t_end:g}: "
                    f"{count['run']} to run, {count['resume']} to resume, {count['done']} done, "
                    f"{count['failed']} failed",
                    flush=True,
                )
                for p in plan:
                    if p.action == "failed":
                        kept_failed.append(p)
                        print(f"  seed {p.seed}: {p.note} (kept; --force reruns it)", flush=True)
            print(f"{report.total} seeds of {len(planned)} studies on {where}", flush=True)

        started = time.perf_counter()
        try:
            ran = run_studies(
                picked, args.runs, pool=pool, force=args.force, report=report, announce=announce, older_than=older_than
            )
        except EnsembleError as exc:
            raise CliError(str(exc)) from None
    print(f"ran {counted(report.done, 'seed')} in {time.perf_counter() - started:.1f} s", flush=True)
    statuses = [r.get("status") if r is not None else None for _, results in ran for r in results]
    if "io_error" in statuses:  # no summary: there is no room for it either
        from ..lifecycle import ABANDONED

        raise CliIOError(
            "a seed could not write its file (above); every seed file keeps its frames and checkpoint: free "
            "some space (or fix the folder) and run the same command again to continue",
            hard_exit=bool(ABANDONED),
        )
    for ens, results in ran:
        summary = ens.summarise()
        if summary["n_seeds"]:
            try:
                js, _ = write_summary(summary, ens.folder)
            except (EnsembleError, OSError) as exc:
                raise write_failed(f"cannot write the summary into {ens.folder}", exc) from None
            print(f"study {ens.folder.name}: wrote {js} (selfas-graph study summarise {ens.folder.name}: the page's)")
    if "interrupted" in statuses or None in statuses:
        print("selfas-graph study run: interrupted; run the same command again to continue", file=sys.stderr)
        return interrupted_code(r for _, results in ran for r in results)
    if "error" in statuses:
        print("selfas-graph study run: some seeds stopped with an error (above)", file=sys.stderr)
        return 1
    return EXIT_NUMERICAL if "failed" in statuses or kept_failed else 0


def run(args):
    from ..studies import StudiesError

    try:
        return _run(args)
    except StudiesError as exc:  # a study's scenario file that cannot be read, for its tables and figures
        raise CliError(str(exc)) from None


def _check_options(args):
    """An option (or study names) the action does not read is refused by name: it was taken and ignored
    (``study list --check``, ``study page fig2``). The options' defaults are the parser's."""
    given = {d for d in _OPTIONS if getattr(args, d) != args._defaults[d]} | ({"names"} if args.names else set())
    for dest in sorted(given):
        if dest not in USED[args.action]:
            users = " and ".join(a for a, used in USED.items() if dest in used)
            what = "study names are" if dest == "names" else f"--{dest.replace('_', '-')} is"
            raise CliError(
                f"{what} read by {users}, not by {args.action}: leave {'them' if dest == 'names' else 'it'} out"
            )


def _run(args):
    _check_options(args)
    studies = _studies(args)
    if args.figures is None:  # beside the page whose figures they are
        args.figures = str(Path(args.page).parent / FIGURES_BESIDE_PAGE)
    actions = {"list": _list, "run": _run_studies, "summarise": _summarise, "page": _page}
    return actions[args.action](args, studies)


def _list(args, studies):
    """``study list``: each study, its scene and its seeds (a percolation study also its rod counts and fields)."""
    for s in studies.studies.values():
        extra = f" {' '.join('--set ' + o for o in s.overrides)}" if s.overrides else ""
        if s.kind == "percolation":  # its rod counts and fields: what its runs are (bench percolation)
            counts = ", ".join(str(c) for c in s.counts)
            extra += f", percolation over {counts} rods, fields {s.fields},"
            print(
                f"{s.name}: {s.title}: {s.scenario}{extra} {s.seeds} seeds each to the short circuit or t = {s.t_end:g}"
            )
            continue
        print(f"{s.name}: {s.title}: {s.scenario}{extra}, {s.seeds} seeds to t = {s.t_end:g}")
    return 0


def _run_studies(args, studies):
    """``study run NAME...``: the seeds of the ensembles in one pool, then the percolation studies."""
    if not args.names:
        raise CliError("study run needs the names of the studies to run (selfas-graph study list shows them)")
    from .._version import __version__
    from .main import main

    code = 0
    picked = _pick(studies, args.names)
    since = studies.trajectories_since
    from ..studies import later_version

    newest = functools.reduce(later_version, (studies.since(s.name) for s in picked), since)
    if older_version(__version__, newest):
        raise CliError(
            f"this installation reports version {__version__}, older than trajectories_since = {newest} in "
            f"{args.studies}: its runs would be taken for older ones; install the package again (pip install -e .)"
        )
    old = [
        f"{out} was made by version {made_by}, before the trajectories of version {studies.since(s.name)}"
        for s in picked
        if s.kind == "percolation" and not args.force
        for out in [Path(args.runs) / s.name / PERCOLATION_JSON]
        if out.exists() and older_version(made_by := _percolation_version(out), studies.since(s.name))
    ]
    if old:  # refused before anything runs, as a seed file of an older version is
        raise CliError(
            "result files that cannot be used (docs/studies.toml trajectories_since):\n  "
            + "\n  ".join(old)
            + "\npass --force to run them again"
        )
    ensembles = [s for s in picked if s.kind != "percolation"]
    if ensembles:  # their seeds in one pool: no worker waits for the end of a study
        code = _run_together(ensembles, args, since)
        if code is None:
            return 0  # an MPI worker rank: rank 0 runs the rest
        if code in (2, 4) or code > 128:  # bad input, an I/O error, a signal
            return code
    for s in picked:
        if s.kind != "percolation":
            continue
        out = Path(args.runs) / s.name / PERCOLATION_JSON
        if out.exists() and not args.force:
            print(f"study {s.name}: {out} exists (--force runs it again)")
            continue
        out.parent.mkdir(parents=True, exist_ok=True)
        argv = ["bench", "percolation", s.scenario, "--counts", *map(str, s.counts), "--seeds", str(s.seeds)]
        argv += ["--first-seed", str(s.first_seed), "--t-max", repr(s.t_end), "--fields", s.fields]
        argv += ["--workers", str(args.jobs), "-o", str(out)] + [f"--set={o}" for o in s.overrides]
        print(f"study {s.name}: selfas-graph {' '.join(argv)}", flush=True)
        code = main(argv) or code
    return code


def _summarise(args, studies):
    """``study summarise [NAME...]``: each study's summary from its run files, and its figures."""
    from ..studies import summarise_study, write_json_atomic

    skipped = []
    for s in _pick(studies, args.names):
        if s.kind == "percolation":
            from ..studies.summary import percolation_summary

            src = Path(args.runs) / s.name / PERCOLATION_JSON
            if not src.exists():
                print(f"study {s.name}: no {src}; skipped")
                skipped.append(s.name)
                continue
            summary = percolation_summary(s, src)
            out = write_json_atomic(summary, Path(args.summaries) / f"{s.name}.json")
            print(f"study {s.name}: {len(summary['densities'])} densities summarised into {out}")
            continue
        if not (Path(args.runs) / s.name).is_dir():
            print(f"study {s.name}: no run files in {Path(args.runs) / s.name}; skipped")
            skipped.append(s.name)
            continue
        summary = summarise_study(s, args.runs, studies)
        if not summary["n_seeds"]:
            print(f"study {s.name}: no readable seed file; skipped")
            skipped.append(s.name)
            continue
        # the movie the page links (None: none made with this summary, and an older one is not linked)
        movie = None
        if s.section in ("paper", "contrast") and not (args.no_figures or args.no_movie):
            from .movie import ffmpeg_path

            movie = f"{s.name}_movie.{'mp4' if ffmpeg_path() else 'gif'}"  # MP4 where ffmpeg is there
        summary["movie"] = movie
        try:
            out = write_json_atomic(summary, Path(args.summaries) / f"{s.name}.json")
        except OSError as exc:
            raise write_failed(f"cannot write the summary of {s.name}", exc) from None
        print(f"study {s.name}: {summary['n_seeds']} seeds summarised into {out}")
        if not args.no_figures:
            from ..studies.figures import study_figures

            for path in study_figures(s, summary, args.figures):
                print(f"  wrote {path}")
            from .main import main

            first = Path(args.runs) / s.name / summary["seeds"][0]["path"]
            snap = Path(args.figures) / f"{s.name}_snapshot.png"
            main(["plot", str(first), "--kind", "snapshot", "-o", str(snap), "--force"])
            if movie is not None:
                # the first seed's movie, at most MOVIE_FRAMES frames
                from ..io.h5md import RunFile

                with RunFile(first) as run:
                    every = max(1, -(-run.n_frames // MOVIE_FRAMES))
                argv = ["plot", str(first), "--movie", str(Path(args.figures) / movie), "--every", str(every)]
                if main(argv + ["--force"]) != 0:  # not made: the page must not link an older one
                    summary["movie"] = None
                    write_json_atomic(summary, out)
    if skipped and args.names:  # studies asked for by name, not summarised: not a success
        print(f"selfas-graph study summarise: nothing to summarise for {', '.join(skipped)}", file=sys.stderr)
        return 1
    return 0


def _page(args, studies):
    """``study page [--check]``: the results page's generated blocks and figures from the summaries."""
    from ..studies.page import page_blocks, replace_blocks

    page = Path(args.page)
    if not Path(args.summaries).is_dir():  # every block would say "not run yet" and the page lose its tables
        raise CliError(
            f"the summaries folder {args.summaries} does not exist; give the folder of NAME.json (--summaries)"
        )
    try:
        text = page.read_text(encoding="utf-8")
    except OSError as exc:
        raise CliError(f"cannot read the results page {page}: {exc.strerror or exc}") from None
    import os

    links = Path(os.path.relpath(Path(args.figures).resolve(), page.resolve().parent)).as_posix()  # as the page links
    new, missing = replace_blocks(text, page_blocks(studies, args.summaries, links))
    if not (args.check or args.no_figures):
        from ..studies.figures import plot_sweep
        from ..studies.page import load_summary

        summaries = {n: load_summary(args.summaries, n) for n in studies.studies}
        summaries = {k: v for k, v in summaries.items() if v is not None}
        from ..studies.figures import study_figures

        for name, st in studies.studies.items():  # the figures made from a summary, drawn again from it
            if name in summaries and summaries[name].get("kind") != "percolation":
                for path in study_figures(st, summaries[name], args.figures):
                    print(f"wrote {path}")
        for name in studies.sweeps:
            if sum(summaries.get(st) is not None for _, st in studies.sweep_points(name)) >= 2:
                print(f"wrote {plot_sweep(studies, summaries, name, Path(args.figures) / f'sweep_{name}.png')}")
    for key in missing:
        print(f"note: the page's block '{key}' has no summary behind it yet; left as it is")
    if args.check:
        if new != text:
            print(f"{page} is not what the summaries give; run: selfas-graph study page")
            return 1
        print(f"{page} is up to date with the summaries in {args.summaries}")
        return 0
    if new != text:
        from .paths import check_target

        check_target(page, "results page", force=True)  # a regular file: not a device, folder or dangling link
        from ..io.atomic import write_text_atomic

        try:  # through a symbolic link: the file it names changes, not the link
            write_text_atomic(page, new)
        except OSError as exc:
            raise write_failed(f"cannot write the results page {page}", exc) from None
        print(f"wrote {page}")
    else:
        print(f"{page} already up to date")
    return 0
