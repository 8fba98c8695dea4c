"""Where a step goes: the CPU time of a run's steps, by part, from a checkpoint or a fresh scene.

The launcher of ``selfas-graph bench profile``: ``python tools/bench_profile.py --help``.
"""

import sys

from selfas_graph.cli.main import main

sys.exit(main(["bench", "profile", *sys.argv[1:]]))
