"""Why a network drifts outwards: radial forces on the rods of a run's last frame, by term.

The launcher of ``selfas-graph bench radial_forces``: ``python tools/radial_forces.py --help``.
"""

import sys

from selfas_graph.cli.main import main

sys.exit(main(["bench", "radial_forces", *sys.argv[1:]]))
