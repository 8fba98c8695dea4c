"""Neighbour-list and Yukawa benchmark: the list builds and the sum over the rod-centre list, per instruction set.

The launcher of ``selfas-graph bench neighbours``: ``python tools/bench_neighbours.py --help``.
"""

import sys

from selfas_graph.cli.main import main

sys.exit(main(["bench", "neighbours", *sys.argv[1:]]))
