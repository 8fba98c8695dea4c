"""Tip-tip force benchmark: the multipole tree against the direct sum.

The launcher of ``selfas-graph bench tree``: ``python tools/bench_tree.py --help``.
"""

import sys

from selfas_graph.cli.main import main

sys.exit(main(["bench", "tree", *sys.argv[1:]]))
