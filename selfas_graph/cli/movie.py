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
from .main import CliError, write_failed
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


class _Gif:
    """Frames gathered as a palette GIF (Pillow), saved at the end."""

    def __init__(self, path):
        self.path, self.images = path, []

    def add(self, rgb):
        from PIL import Image

        self.images.append(Image.fromarray(np.ascontiguousarray(rgb)).quantize(colors=128))

    def finish(self):
        self.images[0].save(self.path, save_all=True, append_images=self.images[1:], duration=1000 // FPS, loop=0)

    def abandon(self):
        pass


class _Mp4:
    """Frames piped to ffmpeg as raw RGB, H.264 at even sizes (cropped by at most a pixel)."""

    def __init__(self, path, ffmpeg, out):
        self.path, self.ffmpeg, self.out, self.proc, self.shape = path, ffmpeg, out, None, None

    def add(self, rgb):
        if self.proc is None:
            h, w = rgb.shape[:2]
            self.shape = (h - h % 2, w - w % 2)  # H.264 takes even sizes
            self.proc = subprocess.Popen(
                [self.ffmpeg, "-loglevel", "error", "-y", "-f", "rawvideo", "-pix_fmt", "rgb24"]
                + ["-s", f"{self.shape[1]}x{self.shape[0]}", "-r", str(FPS), "-i", "-", "-vcodec", "libx264"]
                + ["-pix_fmt", "yuv420p", str(self.path)],
                stdin=subprocess.PIPE,
            )
        self.proc.stdin.write(np.ascontiguousarray(rgb[: self.shape[0], : self.shape[1]]).tobytes())

    def finish(self):
        self.proc.stdin.close()
        if self.proc.wait() != 0:
            raise CliError(f"ffmpeg could not write {self.out}")
        self.proc = None

    def abandon(self):
        if self.proc is not None:
            self.proc.kill()
            self.proc.wait()


def _draw_frames(run, frames, args, Figure, dpi, sink, name):
    """Each frame's snapshot into ``sink``, in one box that holds the rods of every frame drawn."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from tqdm import tqdm

    from .plots.frame import _figsize, _snapshot

    pos = run.f[layout.TIP_POSITION_VALUE]
    lo = np.min([pos[k].min(axis=0) for k in frames], axis=0)
    hi = np.max([pos[k].max(axis=0) for k in frames], axis=0)
    args.bounds = (lo, hi)
    size = None
    for k in tqdm(frames, desc=f"movie {name}", unit="frame", disable=None):
        frame = run.frame(k)
        if frame.gap is not None:
            args.bounds = (
                np.array([lo[0], lo[1], min(lo[2], -frame.gap / 2)]),
                np.array([hi[0], hi[1], max(hi[2], frame.gap / 2)]),
            )
        size = size or _figsize("snapshot", frame)
        fig = Figure(figsize=size, layout="constrained")
        _snapshot(fig, run, frame, args)
        canvas = FigureCanvasAgg(fig)
        fig.set_dpi(dpi)
        canvas.draw()
        sink.add(np.asarray(canvas.buffer_rgba())[..., :3])


def _checked_target(args):
    """The movie's path (through a symbolic link, the file it names), its suffix and ffmpeg (for MP4),
    after the checks of its name, kind, program and folder."""
    out = Path(args.movie)
    kind = out.suffix.lower()
    if kind not in (".gif", ".mp4"):
        raise CliError(f"--movie {out}: the movie must end in .gif or .mp4")
    if args.kind != "snapshot":
        raise CliError("--movie renders snapshots; leave out --kind or give --kind snapshot")
    ffmpeg = ffmpeg_path() if kind == ".mp4" else None
    if kind == ".mp4" and ffmpeg is None:
        raise CliError('an MP4 needs ffmpeg: pip install "selfas-graph[movie]" (or write a .gif)')
    check_target(out, "movie", force=args.force, inputs=[Path(args.run)], keep_hdf5=True, name_option="--movie")
    check_folder(out, "movie")
    return out.resolve(), kind, ffmpeg


def render_movie(args, Figure) -> int:
    out, kind, ffmpeg = _checked_target(args)
    dpi = MOVIE_DPI if args.dpi is None else args.dpi
    frames, sinks = [], []

    def write(tmp):
        sink = _Gif(tmp) if kind == ".gif" else _Mp4(tmp, ffmpeg, out)
        sinks.append(sink)
        with RunFile(Path(args.run)) as run:
            if run.n_frames == 0:
                raise RunFileError(f"{run.path}: the run has no saved frames")
            frames[:] = _frames(run, args.every)
            try:
                _draw_frames(run, frames, args, Figure, dpi, sink, out.name)
            except RunFileError:
                raise  # the reader's own explanation
            except (KeyError, IndexError, TypeError, AttributeError, ValueError) as exc:
                # the run layout with inconsistent contents, as plot's PNG says (cli/plot.py)
                raise RunFileError(f"{run.path}: inconsistent run data ({type(exc).__name__}: {exc})") from None
        sink.finish()

    try:
        atomic_write(out, write)
    except RunFileError as exc:
        raise CliError(str(exc)) from None
    except OSError as exc:
        raise write_failed(f"cannot write {out}", exc) from None
    finally:
        for sink in sinks:
            sink.abandon()
    print(f"wrote {out} ({len(frames)} frames, {FPS} per second)")
    return 0
