"""Accuracy and cost of the quadrature of the external dipole's line charge (term 11) on a run's state.

The launcher of ``selfas-graph bench line_charge``: ``python tools/line_charge.py --help``.
"""

import sys

from selfas_graph.cli.main import main

sys.exit(main(["bench", "line_charge", *sys.argv[1:]]))
