"""Where and with what a run or a measurement was made: the source commit, the CPU model and the
instruction set numba compiles for. Run files (:func:`selfas_graph.io.h5md.run_provenance`), study
summaries and the benchmarks in ``selfas_graph/bench/`` record them."""

import os
import platform
import re
import subprocess
from functools import lru_cache
from pathlib import Path

__all__ = ["cpu_model", "machine", "numba_target", "older_version", "source_commit", "version_key"]


#: the order of PEP 440's pre-release stages, a release itself after all of them
_STAGES = {"dev": 0, "a": 1, "alpha": 1, "b": 2, "beta": 2, "c": 3, "rc": 3, "pre": 3, "preview": 3}


def version_key(version):
    """A version string as a key that orders versions as PEP 440 does for this project's versions: its
    release numbers without trailing zeros, then its stage (``.dev`` before ``a``, ``b``, ``rc``, the
    release itself last) and the stage's number ("0.4.0+source" -> ((0, 4), 4, 0), "0.4.3.dev1" ->
    ((0, 4, 3), 0, 1), after "0.4.3.dev0"); None when the string does not start with a release number
    ("", "unknown")."""
    m = re.match(r"(\d+(?:\.\d+)*)(.*)", str(version or "").strip())
    if not m:
        return None
    release = [int(x) for x in m.group(1).split(".")]
    while len(release) > 1 and release[-1] == 0:
        release.pop()
    pre = re.match(r"[.-]?(alpha|beta|preview|pre|dev|rc|a|b|c)(\d*)", m.group(2).lower())
    if not pre:
        return tuple(release), len(set(_STAGES.values())), 0
    return tuple(release), _STAGES[pre.group(1)], int(pre.group(2) or 0)


def older_version(version, since) -> bool:
    """Whether ``version`` (a run's) is older than ``since``; an unreadable one counts as older,
    and nothing is older than an empty ``since``."""
    if not since:
        return False
    key = version_key(version)
    return key is None or key < version_key(since)


@lru_cache(maxsize=None)
def source_commit() -> str:
    """The git commit of the package's source, with ``+dirty`` when its tracked files differ from it,
    or "" when the package is not in a git checkout (an installed wheel)."""
    root = Path(__file__).resolve().parent.parent
    try:
        head = subprocess.run(["git", "-C", str(root), "rev-parse", "HEAD"], capture_output=True, text=True, timeout=10)
        if head.returncode != 0:
            return ""
        dirty = subprocess.run(
            ["git", "-C", str(root), "status", "--porcelain", "--untracked-files=no", "--", "selfas_graph"],
            capture_output=True,
            text=True,
            timeout=10,
        )
    except (OSError, subprocess.SubprocessError):
        return ""
    return head.stdout.strip() + ("+dirty" if dirty.stdout.strip() else "")


def cpu_model() -> str:
    """The CPU model name from /proc/cpuinfo (or what the platform module says)."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def numba_target() -> dict:
    """The CPU numba compiles for and its vector features, as numba's code generator takes them:
    ``NUMBA_CPU_FEATURES`` when set (empty: the named CPU's own), else the host's, also when
    ``NUMBA_CPU_NAME`` names another CPU (numba's ``JITCPUCodegen._get_host_cpu_features``)."""
    import llvmlite.binding as ll
    import numba

    name = numba.config.CPU_NAME or ll.get_host_cpu_name()
    if numba.config.CPU_FEATURES:
        feats = numba.config.CPU_FEATURES.split(",")
    elif numba.config.CPU_FEATURES is not None:
        feats = []  # set empty: the named CPU's own features, which LLVM knows from the name
    else:
        feats = [("+" if on else "-") + k for k, on in ll.get_host_cpu_features().items()]
    vector = sorted(f[1:] for f in feats if f.startswith("+") and (f[1:].startswith(("avx", "fma", "sse4"))))
    if not feats:
        vector = ["(all of " + name + ")"]
    widest = (
        "AVX-512"
        if any(v.startswith("avx512") for v in vector)
        else "AVX2"
        if "avx2" in vector
        else "AVX"
        if "avx" in vector
        else "SSE"
    )
    if not feats:
        widest = {
            "haswell": "AVX2",
            "broadwell": "AVX2",
            "skylake": "AVX2",
            "znver1": "AVX2",
            "znver2": "AVX2",
            "znver3": "AVX2",
            "znver4": "AVX-512",
            "skylake-avx512": "AVX-512",
            "icelake-server": "AVX-512",
            "sapphirerapids": "AVX-512",
            "x86-64": "SSE2",
        }.get(name, "as " + name)
    return {
        "cpu_name": name,
        "set_by": "NUMBA_CPU_NAME" if numba.config.CPU_NAME else "host",
        "widest": widest,
        "vector_features": vector,
        "numba": numba.__version__,
    }


def machine() -> dict:
    """CPU model, core count and the numba target."""
    return {"cpu_model": cpu_model(), "cores": os.cpu_count(), **numba_target()}
