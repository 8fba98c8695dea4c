"""Check that the working tree writes the run files a git commit writes, bit for bit.

The launcher of ``selfas-graph bench same_as_commit``: ``python tools/same_as_commit.py --help``.
"""

import sys

from selfas_graph.cli.main import main

sys.exit(main(["bench", "same_as_commit", *sys.argv[1:]]))
