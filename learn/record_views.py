"""The observation dict over an arrays record, made fast enough for every environment step.

:meth:`sim.observation_arrays.ObservationLayout.arrays` makes each of the ~40 views with its own
``np.ndarray`` call (about 40 µs a record); here the layout is one structured dtype whose fields
are the leaves, and each view is a field of one 0-d array over the record (about 12 µs). The
dicts are the same: keys in the same order, views of the same dtype, shape and bytes.
"""

from __future__ import annotations

import numpy as np

from sim.observation_arrays import ObservationLayout

# (key, field name) of a leaf, or (key, its children) of a nested dict
_Plan = list[tuple[str, "str | _Plan"]]


class RecordViews:
    """Reads records of one :class:`~sim.observation_arrays.ObservationLayout`."""

    def __init__(self, layout: ObservationLayout) -> None:
        names = [".".join(leaf.path) for leaf in layout.leaves]
        self._dtype = np.dtype(
            {
                "names": names,
                "formats": [(np.dtype(leaf.dtype), leaf.shape) for leaf in layout.leaves],
                "offsets": [leaf.offset for leaf in layout.leaves],
                "itemsize": layout.size,
            }
        )
        # The nesting of layout.arrays (a dict per path prefix, keys in order of appearance).
        tree: dict = {}
        for leaf, name in zip(layout.leaves, names, strict=True):
            node = tree
            for key in leaf.path[:-1]:
                node = node.setdefault(key, {})
            node[leaf.path[-1]] = name
        self._plan = _plan(tree)

    def arrays(self, record: bytearray | memoryview) -> dict:
        """The observation dict over ``record``: its arrays are views of it, as
        :meth:`~sim.observation_arrays.ObservationLayout.arrays` gives them."""
        return _read(np.ndarray((), self._dtype, record), self._plan)


def _plan(tree: dict) -> _Plan:
    return [(key, sub if isinstance(sub, str) else _plan(sub)) for key, sub in tree.items()]


def _read(fields: np.ndarray, plan: _Plan) -> dict:
    return {key: fields[sub] if isinstance(sub, str) else _read(fields, sub) for key, sub in plan}
