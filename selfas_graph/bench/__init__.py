"""Benchmarks and tools of selfas-graph: what measures the code and makes its figures and pages.

Each tool is a module with ``main(argv)`` and runs as ``python -m selfas_graph.bench.NAME ...``
or ``selfas-graph bench NAME ...`` (``selfas-graph bench`` lists them). An edge of the package:
it may import any part of it, and nothing in the package imports it but the command line.
"""
