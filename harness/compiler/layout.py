"""Named slices of the compiler's flat vectors (states, discrete states, inputs, parameters, signals)."""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass
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


@dataclass
class Layout:
    """Ordered slots of a flat vector."""

    slots: list[Slot] = field(default_factory=list)

    def add(self, name: str, size: int, unit: str = "1", kind: str = "real", description: str = "") -> Slot:
        cached = self.__dict__.get("_end")  # (slot count, end) after the last add: O(1) appends
        end = cached[1] if cached is not None and cached[0] == len(self.slots) else self.size
        slot = Slot(name, end, size, unit, kind, description)
        self.slots.append(slot)
        self.__dict__["_end"] = (len(self.slots), end + size)
        return slot

    @property
    def size(self) -> int:
        if self._contiguous():
            return self.slots[-1].start + self.slots[-1].size if self.slots else 0
        return sum(s.size for s in self.slots)

    def _contiguous(self) -> bool:
        """Slots added by :meth:`add` follow each other (checked once per new slot, so sizes are O(1))."""
        n = self.__dict__.get("_checked", 0)
        ok = self.__dict__.get("_ok", True)
        for i in range(n, len(self.slots)):
            prev_end = self.slots[i - 1].start + self.slots[i - 1].size if i else 0
            ok = ok and self.slots[i].start == prev_end
        self.__dict__["_checked"], self.__dict__["_ok"] = len(self.slots), ok
        return ok

    def names(self) -> list[str]:
        return [n for s in self.slots for n in s.element_names()]

    def units(self) -> list[str]:
        return [s.unit for s in self.slots for _ in range(s.size)]

    def _by_name(self) -> dict[str, Slot]:
        cache = self.__dict__.get("_names")
        if cache is None or cache[0] != len(self.slots):
            by: dict[str, Slot] = {}
            for s in self.slots:
                by.setdefault(s.name, s)
            cache = (len(self.slots), by)
            self.__dict__["_names"] = cache
        return cache[1]

    def index(self, name: str) -> Slot:
        try:
            return self._by_name()[name]
        except KeyError:
            raise KeyError(name) from None

    def __contains__(self, name: str) -> bool:
        return name in self._by_name()
