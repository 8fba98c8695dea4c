"""``python -m selfas_graph ARGS``: the ``selfas-graph`` command (``cli/main.py``), e.g. where the
console script is not on the PATH, or as ``mpiexec -n 4 python -m selfas_graph simulate SCENARIO``."""

import sys

from .cli.main import main

if __name__ == "__main__":
    sys.exit(main())
