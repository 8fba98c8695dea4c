"""Write the scenario reference ``docs/scenarios.md`` from the schema in ``selfas_graph.model.params``.

The launcher of ``selfas-graph bench scenario_docs``: ``python tools/scenario_docs.py --help``.
"""

import sys

from selfas_graph.cli.main import main

sys.exit(main(["bench", "scenario_docs", *sys.argv[1:]]))
