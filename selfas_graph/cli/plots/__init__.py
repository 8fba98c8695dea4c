"""The kinds of figure of ``selfas-graph plot`` (:mod:`selfas_graph.cli.plot`), one module per kind of
figure: one frame (``frame``), over time (``series``), an ensemble summary (``summary``); what they
share (``style``)."""
