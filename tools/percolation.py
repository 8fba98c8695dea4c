"""Dynamic percolation: short-circuit times over an ensemble of random runs at several rod densities.

The launcher of ``selfas-graph bench percolation``: ``python tools/percolation.py --help``.
"""

import sys

from selfas_graph.cli.main import main

sys.exit(main(["bench", "percolation", *sys.argv[1:]]))
