"""Scaling benchmark: milliseconds per full step of the Fig. 2 scene from 10^3 to 10^5 rods, beside a peer.

The launcher of ``selfas-graph bench scaling``: ``python tools/bench_scaling.py --help``.
"""

import sys

from selfas_graph.cli.main import main

sys.exit(main(["bench", "scaling", *sys.argv[1:]]))
