"""The field helper of the parameter schema: a dataclass field with its documentation and range.

:mod:`selfas_graph.io.scenario` reads this metadata to validate scenario files, and
``selfas-graph bench scenario_docs`` to write docs/scenarios.md.
"""

from dataclasses import field


def spec(default, doc, *, ge=None, gt=None, lt=None, le=None, choices=None, length=None, factory=None):
    """A dataclass field with validation metadata (used by the scenario loader)."""
    meta = dict(doc=doc, ge=ge, gt=gt, lt=lt, le=le, choices=choices, length=length)
    if factory is not None:
        return field(default_factory=factory, metadata=meta)
    return field(default=default, metadata=meta)
