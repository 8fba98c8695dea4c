"""Check that two run files hold the same data, bit for bit.

The launcher of ``selfas-graph bench same_run``: ``python tools/same_run.py --help``.
"""

import sys

from selfas_graph.cli.main import main

sys.exit(main(["bench", "same_run", *sys.argv[1:]]))
