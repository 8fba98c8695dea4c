"""The benchmarks and tools of ``selfas_graph.bench``: ``selfas-graph bench [NAME [ARGS ...]]``.

``selfas-graph bench NAME ARGS ...`` runs the tool NAME in this process with its own arguments
(``selfas-graph bench NAME --help``) and output, as ``python -m selfas_graph.bench.NAME ARGS ...``
does; ``selfas-graph bench`` alone lists the tools, one line each.
"""

from __future__ import annotations

import argparse
import ast
import contextlib
import importlib
import os
import sys
from pathlib import Path

import selfas_graph.bench as bench

from .main import CliError
from .paths import check_target


def add_arguments(p):
    p.add_argument("tool", nargs="?", metavar="NAME", help="the tool to run (without one: list the tools)")
    p.add_argument("tool_args", nargs=argparse.REMAINDER, metavar="ARGS", help="the tool's own arguments")


def tools() -> dict[str, str]:
    """Tool name -> the first line of its docstring, for every module of ``selfas_graph.bench`` with a
    ``main`` (the shared helpers have none). Read from the source: nothing is imported."""
    out = {}
    for path in sorted(Path(bench.__file__).parent.glob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        if any(isinstance(node, ast.FunctionDef) and node.name == "main" for node in tree.body):
            out[path.stem] = (ast.get_docstring(tree) or "").split("\n")[0]
    return out


@contextlib.contextmanager
def _program(name, argv):
    """``sys.argv`` as the tool would see it from its own command line, so that its usage line names
    ``selfas-graph bench NAME``."""
    saved = sys.argv
    sys.argv = [name, *argv]
    try:
        yield
    finally:
        sys.argv = saved


#: the options by which the tools name files they write
OUTPUT_OPTIONS = ("-o", "--output", "--json", "--plot", "--csv", "--out")


def _output_paths(argv) -> list[str]:
    """The files a tool's arguments name for writing (after one of :data:`OUTPUT_OPTIONS`)."""
    out = []
    for k, a in enumerate(argv):
        name, eq, value = a.partition("=")
        if name in OUTPUT_OPTIONS and eq:
            out.append(value)
        elif a in OUTPUT_OPTIONS and k + 1 < len(argv):
            out.append(argv[k + 1])
    return out


def run(args):
    known = tools()
    if args.tool is None:
        width = max(map(len, known))
        for name, line in known.items():
            print(f"{name:<{width}}  {line}")
        print("\nselfas-graph bench NAME --help: a tool's arguments; selfas-graph compare is same_run")
        return 0
    if args.tool not in known:
        raise CliError(f"no tool {args.tool!r}; the tools are: {', '.join(known)}")
    for path in _output_paths(args.tool_args):  # a link to nothing, a folder or a device: refused, untouched
        check_target(path, "output file", force=True)
    module = importlib.import_module(f"{bench.__name__}.{args.tool}")
    # the tool's environment (HDF5 without file locks, to read a running seed's file) for its run alone:
    # a caller in the same process (a notebook, the tests) keeps its own
    env = getattr(module, "COMMAND_ENV", {})
    before = {key: os.environ.get(key) for key in env}
    for key, value in env.items():
        os.environ.setdefault(key, value)
    try:
        with _program(f"selfas-graph bench {args.tool}", args.tool_args):
            result = module.main(args.tool_args)
    finally:
        for key, value in before.items():
            if value is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = value
    # a tool's exit code is what main returns, when that is a number (some return their figures)
    return result if isinstance(result, int) else 0
