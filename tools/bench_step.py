"""Step benchmark: milliseconds per full step for the Fig. 2 scene and a 6000-rod variant.

The launcher of ``selfas-graph bench step``: ``python tools/bench_step.py --help``.
"""

import sys

from selfas_graph.cli.main import main

sys.exit(main(["bench", "step", *sys.argv[1:]]))
