"""Time a scene end to end with the working tree against a git commit, in turns, in one session.

The launcher of ``selfas-graph bench against_commit``: ``python tools/against_commit.py --help``.
"""

import sys

from selfas_graph.cli.main import main

sys.exit(main(["bench", "against_commit", *sys.argv[1:]]))
