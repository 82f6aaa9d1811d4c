"""A flattened graph laid out for compiling: the flat vectors, start values and co-simulation feeds.

Every equation block's states, discrete states, parameters and output ports get contiguous slots, in
block order (so one instance's entries are one run of each vector, which the grouped loops rely on);
the external inputs are the graph's free inputs (``$name``) and the outputs of co-simulation blocks that
equation blocks or graph outputs read. The algebraic-loop check through co-simulation blocks with direct
feedthrough is here too: it needs each equation block's feedthrough, which the schedule derives
(:attr:`Wiring.feed`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from cpgsim.components.core import CoSimBlock, ModelError
from cpgsim.components.graph import AlgebraicLoopError, FlatGraph
from cpgsim.harness.compiler.layout import Layout


class Wiring:
    """Layouts, start values and co-simulation feeds of ``flat`` (see module docstring)."""

    def __init__(self, flat: FlatGraph, dt: float, substeps: int,
                 signatures: dict[str, tuple] | None = None) -> None:
        self.flat = flat
        self.dt = dt
        self.substeps = substeps
        self.eq_blocks = flat.equation_blocks()
        self.cs_blocks = flat.cosim_blocks()
        self.states, self.dstates, self.inputs, self.params, self.sig = (Layout() for _ in range(5))
        self.feed: dict[str, dict[str, Any]] = {}  # eq block path -> output port -> inputs it reads directly
        self.signatures = signatures  # cpgsim.harness.compiler.kinds.leaf_signatures, when already known
        self._layouts()

    def _layouts(self) -> None:
        x0, z0, p0 = [], [], []
        for path, blk in self.eq_blocks.items():
            for s in blk.states.values():
                self.states.add(f"{path}.{s.name}", s.size, s.unit, s.kind, s.description)
                x0 += list(s.start)
            for s in blk.discrete_states.values():
                self.dstates.add(f"{path}.{s.name}", s.size, s.unit, s.kind, s.description)
                z0 += list(s.start)
            for par in blk.parameters.values():
                self.params.add(f"{path}.{par.name}", 1, par.unit, par.kind, par.description)
                p0.append(blk.values[par.name])
            for port in blk.outputs.values():
                self.sig.add(f"{path}.{port.name}", port.size, port.unit, port.kind, port.description)
        for name, port in self.flat.inputs.items():
            self.inputs.add("$" + name, port.size, port.unit, port.kind, port.description)
        # co-simulation outputs that feed equation blocks are external inputs of the compiled part
        needed = {src for dst, src in self.flat.sources.items()
                  if dst.rsplit(".", 1)[0] in self.eq_blocks and src.rsplit(".", 1)[0] in self.cs_blocks}
        needed |= {src for src in self.flat.output_sources.values() if src.rsplit(".", 1)[0] in self.cs_blocks}
        for src in sorted(needed):
            port = self.flat.port(src)
            self.inputs.add(src, port.size, port.unit, port.kind, port.description)
        self.x0, self.z0, self.p0 = (np.array(v, dtype=float) for v in (x0, z0, p0))

    def source_port(self, src: str):
        """The port a source names: a graph input ``$name`` or a block's output ``path.port``."""
        if src.startswith("$"):
            return self.flat.inputs[src[1:]]
        return self.flat.port(src)

    def cosim_feeds(self) -> dict[str, str]:
        """What co-simulation inputs read; also reports algebraic loops through them (needs :attr:`feed`)."""
        cosim_feeds = {}
        for cs_path, blk in self.cs_blocks.items():
            for iname, port in blk.inputs.items():
                key = f"{cs_path}.{iname}"
                if key in self.flat.sources:
                    cosim_feeds[key] = self.flat.sources[key]
                elif port.default is None:
                    raise ModelError(f"input {key} is not connected")
        self._check_cosim_loops()
        return cosim_feeds

    def _check_cosim_loops(self) -> None:
        """Algebraic loops through co-simulation blocks with direct feedthrough."""
        for cs_path, blk in self.cs_blocks.items():
            for out_name, ins in blk.feedthrough.items():
                for in_name in ins:
                    trail = [f"{cs_path}.{out_name}"]
                    if self._reaches(f"{cs_path}.{in_name}", cs_path, trail, set()):
                        raise AlgebraicLoopError(trail[::-1] + [f"{cs_path}.{out_name}"])

    def _reaches(self, input_ref: str, target: str, trail: list[str], seen: set[str]) -> bool:
        """Whether the value of ``input_ref`` depends within the same step on an output of ``target``."""
        src = self.flat.sources.get(input_ref)
        if src is None or src.startswith("$") or src in seen:
            return False
        seen.add(src)
        path, pname = src.rsplit(".", 1)
        trail.append(input_ref)
        trail.append(src)
        if path == target:
            return True
        blk = self.flat.blocks[path]
        if isinstance(blk, CoSimBlock):
            deps = blk.feedthrough.get(pname, set())
        else:
            deps = self.feed[path][pname]
        for d in (name for name in blk.inputs if name in deps):  # in port order: one loop reported, always the same
            if self._reaches(f"{path}.{d}", target, trail, seen):
                return True
        trail.pop()
        trail.pop()
        return False
