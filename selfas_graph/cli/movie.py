"""Movies of a run: ``selfas-graph plot RUN.h5 --movie OUT.gif|OUT.mp4 [--every K] [--dpi D]``.

Every saved frame (or every K-th) is drawn as the ``snapshot`` figure, in one box that holds the
rods of all the frames drawn (so the view does not jump), and written as an animated GIF (Pillow,
which matplotlib brings) or an MP4 (H.264 through ffmpeg: the ``imageio-ffmpeg`` wheel,
``pip install "selfas-graph[movie]"``, or an ffmpeg on the PATH). The movie is written to a
temporary file and renamed into place, so a failed or interrupted render leaves no partial movie.
"""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import numpy as np

from ..io import layout
from ..io.atomic import atomic_write
from ..io.h5md import RunFile, RunFileError
from .main import CliError, CliIOError
from .paths import check_folder, check_target

#: frames per second of the movie
FPS = 10
#: resolution of a movie's frames when --dpi is left at the figures' default
MOVIE_DPI = 80


def ffmpeg_path():
    """The ffmpeg program to write MP4 with (imageio-ffmpeg's, else one on PATH), or None."""
    try:
        import imageio_ffmpeg

        return imageio_ffmpeg.get_ffmpeg_exe()
    except (ImportError, RuntimeError):
        return shutil.which("ffmpeg")


def _frames(run, every):
    n = run.n_frames
    step = every or 1
    return list(range(0, n, step)) + ([n - 1] if (n - 1) % step else [])


def render_movie(args, Figure) -> int:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from tqdm import tqdm

    from .plots.frame import _figsize, _snapshot

    out = Path(args.movie)
    kind = out.suffix.lower()
    if kind not in (".gif", ".mp4"):
        raise CliError(f"--movie {out}: the movie must end in .gif or .mp4")
    if args.kind != "snapshot":
        raise CliError("--movie renders snapshots; leave out --kind or give --kind snapshot")
    ffmpeg = ffmpeg_path() if kind == ".mp4" else None
    if kind == ".mp4" and ffmpeg is None:
        raise CliError('an MP4 needs ffmpeg: pip install "selfas-graph[movie]" (or write a .gif)')
    dpi = MOVIE_DPI if args.dpi is None else args.dpi
    run_path = Path(args.run)
    check_target(out, "movie", force=args.force, inputs=[run_path], keep_hdf5=True, name_option="--movie")
    check_folder(out, "movie")
    out = out.resolve()  # through a symbolic link: the file it names is replaced, not the link
    images, proc, frames = [], None, []

    def write(tmp):
        nonlocal proc
        with RunFile(run_path) as run:
            try:
                draw(run, tmp)
            except RunFileError:
                raise  # the reader's own explanation
            except (KeyError, IndexError, TypeError, AttributeError, ValueError) as exc:
                # the run layout with inconsistent contents, as plot's PNG says (cli/plot.py)
                raise RunFileError(f"{run.path}: inconsistent run data ({type(exc).__name__}: {exc})") from None
        if kind == ".gif":
            images[0].save(tmp, save_all=True, append_images=images[1:], duration=1000 // FPS, loop=0)
        else:
            proc.stdin.close()
            if proc.wait() != 0:
                raise CliError(f"ffmpeg could not write {out}")
            proc = None

    def draw(run, tmp):
        nonlocal proc, frames
        if run.n_frames == 0:
            raise RunFileError(f"{run.path}: the run has no saved frames")
        frames = _frames(run, args.every)
        pos = run.f[layout.TIP_POSITION_VALUE]
        lo = np.min([pos[k].min(axis=0) for k in frames], axis=0)
        hi = np.max([pos[k].max(axis=0) for k in frames], axis=0)
        args.bounds = (lo, hi)
        size = None
        for k in tqdm(frames, desc=f"movie {out.name}", unit="frame", disable=None):
            frame = run.frame(k)
            if frame.gap is not None:
                args.bounds = (
                    np.array([lo[0], lo[1], min(lo[2], -frame.gap / 2)]),
                    np.array([hi[0], hi[1], max(hi[2], frame.gap / 2)]),
                )
            if size is None:
                size = _figsize("snapshot", frame)
            fig = Figure(figsize=size, layout="constrained")
            _snapshot(fig, run, frame, args)
            canvas = FigureCanvasAgg(fig)
            fig.set_dpi(dpi)
            canvas.draw()
            rgb = np.asarray(canvas.buffer_rgba())[..., :3]
            h, w = rgb.shape[:2]
            if kind == ".gif":
                from PIL import Image

                images.append(Image.fromarray(np.ascontiguousarray(rgb)).quantize(colors=128))
            else:
                if proc is None:
                    w2, h2 = w - w % 2, h - h % 2  # H.264 takes even sizes
                    proc = subprocess.Popen(
                        [ffmpeg, "-loglevel", "error", "-y", "-f", "rawvideo", "-pix_fmt", "rgb24"]
                        + ["-s", f"{w2}x{h2}", "-r", str(FPS), "-i", "-", "-vcodec", "libx264"]
                        + ["-pix_fmt", "yuv420p", str(tmp)],
                        stdin=subprocess.PIPE,
                    )
                    shape = (h2, w2)
                proc.stdin.write(np.ascontiguousarray(rgb[: shape[0], : shape[1]]).tobytes())

    try:
        atomic_write(out, write)
    except RunFileError as exc:
        raise CliError(str(exc)) from None
    except OSError as exc:
        raise CliIOError(f"cannot write {out}: {exc.strerror or exc}") from None
    finally:
        if proc is not None:
            proc.kill()
            proc.wait()
    print(f"wrote {out} ({len(frames)} frames, {FPS} per second)")
    return 0
