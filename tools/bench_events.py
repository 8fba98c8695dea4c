"""Cost of contact detection and events, and of a topology update plus circuit solve.

The launcher of ``selfas-graph bench events``: ``python tools/bench_events.py --help``.
"""

import sys

from selfas_graph.cli.main import main

sys.exit(main(["bench", "events", *sys.argv[1:]]))
