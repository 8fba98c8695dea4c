"""Speed-accuracy trade of every accuracy knob of a scene, against a tight reference run.

The launcher of ``selfas-graph bench tradeoff``: ``python tools/tradeoff.py --help``.
"""

import sys

from selfas_graph.cli.main import main

sys.exit(main(["bench", "tradeoff", *sys.argv[1:]]))
