"""The rod currents' field on the tips: the tree against the direct sums, time and error.

The launcher of ``selfas-graph bench current_tree``: ``python tools/bench_current_tree.py --help``.
"""

import sys

from selfas_graph.cli.main import main

sys.exit(main(["bench", "current_tree", *sys.argv[1:]]))
