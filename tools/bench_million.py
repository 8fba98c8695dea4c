"""A scene of 10^5-10^6 rods on one node: peak memory, the tip tree's stages and whole steps.

The launcher of ``selfas-graph bench million``: ``python tools/bench_million.py --help``.
"""

import sys

from selfas_graph.cli.main import main

sys.exit(main(["bench", "million", *sys.argv[1:]]))
