"""The tip tree's walk by part: its lists, near field and far field, and the pairs each group takes.

The launcher of ``selfas-graph bench walk_parts``: ``python tools/bench_walk_parts.py --help``.
"""

import sys

from selfas_graph.cli.main import main

sys.exit(main(["bench", "walk_parts", *sys.argv[1:]]))
