"""Accuracy and cost of the quadrature of term 10 (the Lorentz force on rod currents) on a run's state.

The launcher of ``selfas-graph bench lorentz_rule``: ``python tools/lorentz_rule.py --help``.
"""

import sys

from selfas_graph.cli.main import main

sys.exit(main(["bench", "lorentz_rule", *sys.argv[1:]]))
