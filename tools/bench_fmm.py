"""A fast multipole method for the tip-tip force against the tip tree's walk, in one run.

The launcher of ``selfas-graph bench fmm``: ``python tools/bench_fmm.py --help``.
"""

import sys

from selfas_graph.cli.main import main

sys.exit(main(["bench", "fmm", *sys.argv[1:]]))
