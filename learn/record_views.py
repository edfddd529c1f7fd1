"""The observation dict over an arrays record, made fast enough for every environment step.

:meth:`sim.observation_arrays.ObservationLayout.arrays` makes each of the ~40 views with its own
``np.ndarray`` call (about 40 µs a record); here the layout is one structured dtype whose fields
are the leaves, and each view is a field of one 0-d array over the record (about 12 µs). The
nested dicts are then one expression of dict displays made for the layout (about 7 µs): walking
a plan of the ~40 keys in a loop, testing each for a leaf, cost as much as taking the views. The
dicts are the same: keys in the same order, views of the same dtype, shape and bytes.
"""

from __future__ import annotations

import numpy as np

from sim.observation_arrays import ObservationLayout


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
        # One expression of nested dict displays, compiled once (as dataclasses makes its
        # methods): its constant keys are the fastest way Python builds a dict.
        self._read = eval(f"lambda fields: {_display(tree)}", {})

    def arrays(self, record: bytearray | memoryview) -> dict:
        """The observation dict over ``record``: its arrays are views of it, as
        :meth:`~sim.observation_arrays.ObservationLayout.arrays` gives them."""
        return self._read(np.ndarray((), self._dtype, record))


def _display(tree: dict) -> str:
    """``{key: fields[name], key: {...}, ...}`` for ``tree`` (a field name per leaf)."""
    items = (
        f"{key!r}: {_display(sub) if isinstance(sub, dict) else f'fields[{sub!r}]'}"
        for key, sub in tree.items()
    )
    return "{" + ", ".join(items) + "}"
