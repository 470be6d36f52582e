"""Python data as the YAML it stands for: numpy arrays, numpy scalars and tuples as lists and numbers.

What a Python caller builds (``np.eye(3)``, ``np.int64(10)``, ``(1.0, 2.0)``) is validated by the input models
(:func:`mobisense.core.config.parse_config`) as the YAML value it stands for.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["plain_data"]


def plain_data(data: Any) -> Any:
    """``data`` with numpy arrays and tuples as lists and numpy scalars as Python numbers, recursively.

    What a Python caller builds (``np.eye(3)``, ``np.int64(10)``, ``(1.0, 2.0)``) then validates as the YAML
    value it stands for. Containers holding nothing to convert are returned as they are (no copy): a parsed
    YAML document costs one pass over its containers.
    """
    kind = type(data)
    if kind is list and all(map(_PLAIN.__contains__, map(type, data))):  # at C speed: vectors, matrix rows
        return data
    if kind is dict or kind is list:
        out = None
        for key, value in data.items() if kind is dict else enumerate(data):
            if type(value) not in _PLAIN and (plain := plain_data(value)) is not value:
                if out is None:
                    out = kind(data)
                out[key] = plain
        return data if out is None else out
    if kind in _PLAIN:
        return data
    if isinstance(data, np.ndarray):
        return data.tolist()
    if isinstance(data, np.generic):
        return data.item()
    if isinstance(data, dict):  # a mapping or sequence of another type: a dict or list of plain values
        return {key: plain_data(value) for key, value in data.items()}
    if isinstance(data, (list, tuple)):
        return [plain_data(value) for value in data]
    return data


#: the types of YAML's scalar values: nothing to convert
_PLAIN = frozenset({float, int, str, bool, type(None)})
