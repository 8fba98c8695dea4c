"""What rods that differ cost: equal rods against per-rod lengths, resistances and contacts.

The launcher of ``selfas-graph bench rods``: ``python tools/bench_rods.py --help``.
"""

import sys

from selfas_graph.cli.main import main

sys.exit(main(["bench", "rods", *sys.argv[1:]]))
