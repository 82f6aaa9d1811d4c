"""The FMU importer's value conversions (pure functions, no FMU): FMI type names to the block library's kinds,
numbers read from ``modelDescription.xml`` (start, min, max) checked against their type's range, start
texts (a Boolean's ``true``/``1``, an array's space-separated values), and port values converted to what an
FMI setter takes (Int64/UInt64 exact, integer types rounded and range-checked, Boolean by the 0/1 flag
rule ``> 0.5``).

:mod:`cpgsim.fmus.importer.description` and :mod:`cpgsim.fmus.importer.runtime` use them; they live here so
that ``tests/test_importer_values.py`` (quick tier) and ``benchmarks/mutation.py`` can test them alone.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from cpgsim.fmus.errors import ModelDescriptionError

REAL_TYPES = {"Real", "Float64", "Float32"}
INT_TYPES = {"Integer", "Int8", "UInt8", "Int16", "UInt16", "Int32", "UInt32", "Int64", "UInt64", "Enumeration"}
BOOL_TYPES = {"Boolean"}

INT_RANGES = {"Integer": (-2**31, 2**31 - 1), "Enumeration": (-2**31, 2**31 - 1), "Int8": (-2**7, 2**7 - 1),
              "UInt8": (0, 2**8 - 1), "Int16": (-2**15, 2**15 - 1), "UInt16": (0, 2**16 - 1),
              "Int32": (-2**31, 2**31 - 1), "UInt32": (0, 2**32 - 1), "Int64": (-2**63, 2**63 - 1),
              "UInt64": (0, 2**64 - 1)}
"""The value range of each FMI integer type (``Integer`` and ``Enumeration`` are FMI 2's 32-bit ``int``)."""
_FLOAT_WORDS = {"inf", "+inf", "-inf", "infinity", "+infinity", "-infinity", "nan"}

EXACT_INT = {"Int64": np.int64, "UInt64": np.uint64}
"""FMI 3 types whose values do not all fit a float64: kept as exact integers end to end."""
_INT_RANGE = {"Int64": (-2 ** 63, 2 ** 63 - 1), "UInt64": (0, 2 ** 64 - 1)}
# the integer types whose setter takes a C integer narrower than 64 bits (ctypes wraps a value outside it
# silently: 300 set to an Int8 arrives as 44); Enumeration is left out: FMI 2 sets it as an int, FMI 3 as
# an Int64
_NARROW_INT = ("Integer", "Int8", "UInt8", "Int16", "UInt16", "Int32", "UInt32")


def show(value: Any) -> str:
    """A number as an error message prints it: an integer (a Python, numpy or integral float value) with every
    digit, another float as its shortest repr (``2.5``, ``nan``); never a numpy repr (``np.float64(-1.0)``)."""
    if isinstance(value, (bool, np.bool_)):
        return "true" if value else "false"
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    try:
        f = float(value)
    except (TypeError, ValueError):
        return repr(value)
    return str(int(f)) if math.isfinite(f) and f.is_integer() else repr(f)


def kind_of(fmi_type: str) -> str | None:
    if fmi_type in REAL_TYPES:
        return "real"
    if fmi_type in INT_TYPES:
        return "integer"
    if fmi_type in BOOL_TYPES:
        return "boolean"
    return None


def number_attribute(text: Any, element: str, attribute: str, fmi_type: str = "Real") -> float | int:
    """The number in ``attribute`` of ``element`` (e.g. ``<Integer start>`` of variable 'n'), checked.

    An integer type's value must be an integer within the type's range, returned as an exact Python
    ``int`` (an Int64/UInt64 start such as 2^62 + 1 does not fit a float64); a real one a float64 (an overflow
    such as ``1e400`` is out of range; ``INF`` written as such stays infinite). Anything else is a
    :class:`ModelDescriptionError` naming the element and the attribute.
    """
    token = str(text).strip()
    where = f"{element}: attribute {attribute}={token!r}"
    if fmi_type in INT_TYPES:
        try:
            value = int(token)
        except ValueError:
            raise ModelDescriptionError(f"{where} is not an integer ({fmi_type})") from None
        lo, hi = INT_RANGES[fmi_type]  # every one of INT_TYPES has its range (a test holds the two equal)
        if not lo <= value <= hi:
            raise ModelDescriptionError(f"{where} is out of range for {fmi_type} [{lo}, {hi}]")
        return value
    try:
        value = float(token)
    except ValueError:
        raise ModelDescriptionError(f"{where} is not a number") from None
    if not math.isfinite(value) and token.lower() not in _FLOAT_WORDS:
        raise ModelDescriptionError(f"{where} is out of range for a 64-bit float")
    return value


def start_values(raw: Any, fmi_type: str, count: int, name: str) -> tuple[float | int, ...] | None:
    """The ``start`` attribute ``raw`` of variable ``name`` as ``count`` values (one value is repeated for
    every element; ``None`` without a start). Boolean: ``true``/``1`` is 1.0, anything else 0.0."""
    if raw is None:
        return None
    text = str(raw).strip()
    if fmi_type in BOOL_TYPES:
        vals = [1.0 if t in ("true", "1") else 0.0 for t in text.split()]
    else:
        element = f"variable {name!r} <{fmi_type}>"
        vals = [number_attribute(t, element, "start", fmi_type) for t in text.split()]
    if len(vals) == 1 and count > 1:
        vals = vals * count
    if len(vals) != count:
        raise ModelDescriptionError(f"variable {name!r}: {len(vals)} start values for {count} elements")
    return tuple(vals)


def exact_integers(value: Any, fmi_type: str, where: str) -> tuple[int, ...]:
    """``value`` (nested lists / array of integers) as exact Python ints, row-major, in ``fmi_type``'s range."""
    from cpgsim.components.core import ParameterError

    out = [int(v) for v in np.asarray(value, dtype=object).ravel()]
    lo, hi = INT_RANGES.get(fmi_type, (-2 ** 63, 2 ** 64 - 1))
    bad = [v for v in out if not lo <= v <= hi]
    if bad:
        raise ParameterError(f"{where}: {bad[0]} is out of range for {fmi_type} [{lo}, {hi}]")
    return tuple(out)


def as_values(value: Any, fmi_type: str) -> np.ndarray:
    """A port value as a flat array: float64, or exact int64/uint64 for the 64-bit integer types. A value of
    a narrower integer type must round to an integer in the type's range (a ValueError otherwise)."""
    if fmi_type not in EXACT_INT:
        arr = np.atleast_1d(np.asarray(value, dtype=float)).ravel()
        if fmi_type in _NARROW_INT:
            lo, hi = INT_RANGES[fmi_type]
            for v in arr:
                if not (math.isfinite(v) and lo <= round(v) <= hi):
                    raise ValueError(f"{show(v)} is not a {fmi_type} value (an integer in [{lo}, {hi}])")
        return arr
    # a list of Python ints stays ints: numpy would make [1, 2**63 + 1] a float64 array (and 2**63 + 1 2**63)
    arr = np.atleast_1d(value if isinstance(value, np.ndarray) else np.asarray(value, dtype=object)).ravel()
    if arr.dtype.kind in "iu" and arr.dtype != np.dtype(EXACT_INT[fmi_type]):
        arr = np.array([int(v) for v in arr], dtype=object)
    if arr.dtype.kind not in "iu":  # floats or Python ints: exact conversion with a range check
        lo, hi = _INT_RANGE[fmi_type]
        ints = []
        for v in arr:
            iv = int(v) if isinstance(v, (int, np.integer)) or float(v).is_integer() else None
            if iv is None or not lo <= iv <= hi:
                raise ValueError(f"{show(v)} is not a {fmi_type} value (an integer in [{lo}, {hi}])")
            ints.append(iv)
        arr = np.array(ints, dtype=EXACT_INT[fmi_type])
    return arr


def to_fmi(fmi_type: str, values: np.ndarray) -> list:
    """The values an FMI setter of ``fmi_type`` takes: exact ints, bools (``> 0.5``), floats, or the nearest
    integer."""
    if fmi_type in EXACT_INT:
        return [int(v) for v in values]
    if fmi_type == "Boolean":
        return [bool(v > 0.5) for v in values]
    if fmi_type in ("Real", "Float64", "Float32"):
        return [float(v) for v in values]
    return [int(round(float(v))) for v in values]
