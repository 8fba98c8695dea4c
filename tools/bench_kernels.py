"""Kernel benchmark: the hot kernels of a step, one at a time, per instruction set.

The launcher of ``selfas-graph bench kernels``: ``python tools/bench_kernels.py --help``.
"""

import sys

from selfas_graph.cli.main import main

sys.exit(main(["bench", "kernels", *sys.argv[1:]]))
