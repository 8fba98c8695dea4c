"""Make the paper-style figures of one run into a folder (the pictures of docs/results.md).

The launcher of ``selfas-graph bench figures``: ``python tools/figures.py --help``.
"""

import sys

from selfas_graph.cli.main import main

sys.exit(main(["bench", "figures", *sys.argv[1:]]))
