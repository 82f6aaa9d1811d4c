"""Named slices of the compiler's flat vectors (states, discrete states, inputs, parameters, signals)."""

from __future__ import annotations

import operator
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

_SIZE = operator.attrgetter("size")


@dataclass(slots=True)
class Slot:
    """A named slice of a flat vector (state, input, parameter or signal)."""

    name: str
    start: int
    size: int
    unit: str = "1"
    kind: str = "real"
    description: str = ""

    @property
    def slice(self) -> slice:
        return slice(self.start, self.start + self.size)

    def element_names(self) -> list[str]:
        return [self.name] if self.size == 1 else [f"{self.name}[{i}]" for i in range(self.size)]


class Layout:
    """Ordered slots of a flat vector.

    Slots come from :meth:`add` (one at a time) or :meth:`extend` (one per declaration of many blocks). Those of
    :meth:`extend` are made when first read (:attr:`slots`, :meth:`index`, :meth:`names`, ...): a compile of
    thousands of blocks lays out tens of thousands of slots, and a model loaded from the compile cache reads
    few of them (a run reads the signals', rarely the parameters'). What they will be is fixed when
    :meth:`extend` is called: the declarations are frozen objects, kept as given, and :attr:`size` counts them
    at once.
    """

    def __init__(self, slots: list[Slot] | None = None) -> None:
        self._slots: list[Slot] = [] if slots is None else slots
        # runs of slots not made yet: (first start, prefixes, declarations), contiguous and after every made slot
        self._pending: list[tuple[int, Sequence[str], Sequence[Any]]] = []
        self._pending_end = 0
        self._end: tuple[int, int] | None = None  # (slot count, end) after the last add: O(1) appends
        self._checked = 0
        self._ok = True
        self._names: tuple[int, dict[str, Slot]] | None = None

    @property
    def slots(self) -> list[Slot]:
        if self._pending:
            self._make_pending()
        return self._slots

    @slots.setter
    def slots(self, value: list[Slot]) -> None:
        self._pending.clear()
        self._slots = value

    def __repr__(self) -> str:
        return f"Layout(slots={self.slots!r})"

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Layout) and self.slots == other.slots

    __hash__ = None  # type: ignore[assignment]  # mutable, as the dataclass it was

    def add(self, name: str, size: int, unit: str = "1", kind: str = "real", description: str = "") -> Slot:
        slots = self.slots
        cached = self._end
        end = cached[1] if cached is not None and cached[0] == len(slots) else self.size
        slot = Slot(name, end, size, unit, kind, description)
        slots.append(slot)
        self._end = (len(slots), end + size)
        return slot

    def extend(self, prefixes: Sequence[str], declarations: Sequence[Any]) -> None:
        """One slot ``prefix.name`` per declaration, in order, as :meth:`add` would make them: each declaration
        (a :class:`~cpgsim.components.core.State`, :class:`~cpgsim.components.core.Parameter` or
        :class:`~cpgsim.components.core.Port`, all frozen) gives the slot's name, size, unit, kind and
        description. Made on first read (see the class docstring)."""
        if len(prefixes) != len(declarations):
            raise ValueError(f"{len(prefixes)} prefixes for {len(declarations)} declarations")
        if not declarations:
            return
        start = self.size
        self._pending.append((start, prefixes, declarations))
        self._pending_end = start + sum(map(_SIZE, declarations))

    def _make_pending(self) -> None:
        runs, self._pending = self._pending, []
        slots = self._slots
        checked = self._checked == len(slots)  # every slot before checked: the runs follow them (see extend)
        for start, prefixes, declarations in runs:
            for prefix, d in zip(prefixes, declarations, strict=True):
                size = d.size
                slots.append(Slot(f"{prefix}.{d.name}", start, size, d.unit, d.kind, d.description))
                start += size
        self._end = (len(slots), start)
        if checked:
            self._checked = len(slots)

    @property
    def size(self) -> int:
        if self._pending:
            return self._pending_end
        if self._contiguous():
            return self._slots[-1].start + self._slots[-1].size if self._slots else 0
        return sum(s.size for s in self._slots)

    def _contiguous(self) -> bool:
        """Slots added by :meth:`add` follow each other (checked once per new slot, so sizes are O(1))."""
        slots = self._slots
        n, ok = self._checked, self._ok
        for i in range(n, len(slots)):
            prev_end = slots[i - 1].start + slots[i - 1].size if i else 0
            ok = ok and slots[i].start == prev_end
        self._checked, self._ok = len(slots), ok
        return ok

    def names(self) -> list[str]:
        return [n for s in self.slots for n in s.element_names()]

    def units(self) -> list[str]:
        return [s.unit for s in self.slots for _ in range(s.size)]

    def _by_name(self) -> dict[str, Slot]:
        slots = self.slots
        cache = self._names
        if cache is None or cache[0] != len(slots):
            by: dict[str, Slot] = {}
            for s in slots:
                by.setdefault(s.name, s)
            cache = (len(slots), by)
            self._names = cache
        return cache[1]

    def index(self, name: str) -> Slot:
        try:
            return self._by_name()[name]
        except KeyError:
            raise KeyError(name) from None

    def __contains__(self, name: str) -> bool:
        return name in self._by_name()
