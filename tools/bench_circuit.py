"""Time the topology (``classify_rods``) and the circuit solve (``solve_circuit``).

The launcher of ``selfas-graph bench circuit``: ``python tools/bench_circuit.py --help``.
"""

import sys

from selfas_graph.cli.main import main

sys.exit(main(["bench", "circuit", *sys.argv[1:]]))
