"""The per-step checks that became kernels, against the numpy code they replace, in one process.

The launcher of ``selfas-graph bench checks``: ``python tools/bench_checks.py --help``.
"""

import sys

from selfas_graph.cli.main import main

sys.exit(main(["bench", "checks", *sys.argv[1:]]))
