"""Make the paper-style figures of one run into a folder (the pictures of docs/results.md).

Usage: selfas-graph bench figures RUN.h5 OUTDIR [--prefix NAME]

Writes NAME_snapshot_start.png (frame 0), NAME_snapshot_end.png, NAME_density.png,
NAME_field.png, NAME_flux.png and NAME_timeline.png (last frame unless said otherwise), and
with ``--claims`` the time series NAME_moment.png, NAME_fractal.png and NAME_skeleton.png
(docs/model.md "Measures of the paper's claims"), through ``selfas-graph plot``.
"""

import argparse
import sys
from pathlib import Path

from selfas_graph.cli.main import main as cli


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run")
    ap.add_argument("outdir")
    ap.add_argument("--prefix", help="file name prefix (default: the run file's stem)")
    ap.add_argument("--claims", action="store_true", help="also the moment, fractal and skeleton time series")
    args = ap.parse_args(argv)
    out = Path(args.outdir)
    out.mkdir(parents=True, exist_ok=True)
    name = args.prefix or Path(args.run).stem
    jobs = [
        ("snapshot", "0", "snapshot_start"),
        ("snapshot", "-1", "snapshot_end"),
        ("density", "-1", "density"),
        ("field", "-1", "field"),
        ("flux", "-1", "flux"),
        ("timeline", None, "timeline"),
    ]
    if args.claims:
        jobs += [(kind, None, kind) for kind in ("moment", "fractal", "skeleton")]
    for kind, frame, label in jobs:
        argv_ = ["plot", args.run, "--kind", kind, "-o", str(out / f"{name}_{label}.png"), "--force"]
        if frame is not None:
            argv_ += ["--frame", frame]
        code = cli(argv_)
        if code:
            sys.exit(f"plot --kind {kind} failed with exit code {code}")


if __name__ == "__main__":
    main()
