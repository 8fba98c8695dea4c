"""Short-circuit episodes of runs: how long the gap stays closed, what opens it, and the currents.

The launcher of ``selfas-graph bench short_circuits``: ``python tools/short_circuits.py --help``.
"""

import sys

from selfas_graph.cli.main import main

sys.exit(main(["bench", "short_circuits", *sys.argv[1:]]))
