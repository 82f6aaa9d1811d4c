"""A flattened graph laid out for compiling: the flat vectors, start values and co-simulation feeds.

Every equation block's states, discrete states, parameters and output ports get contiguous slots, in
block order (so one instance's entries are one run of each vector, which the grouped loops rely on);
the external inputs are the graph's free inputs (``$name``) and the outputs of co-simulation blocks that
equation blocks or graph outputs read. The algebraic-loop check through co-simulation blocks with direct
feedthrough is here too: it needs each equation block's feedthrough, which the schedule derives
(:attr:`Wiring.feed`).
"""

from __future__ import annotations

import operator
from collections.abc import Callable
from itertools import chain, repeat
from typing import Any

import numpy as np

from cpgsim.components.core import Block, CoSimBlock, ModelError
from cpgsim.components.graph import AlgebraicLoopError, FlatGraph
from cpgsim.harness.compiler.layout import Layout

_START = operator.attrgetter("start")
_NAME = operator.attrgetter("name")


class Wiring:
    """Layouts, start values and co-simulation feeds of ``flat`` (see module docstring)."""

    def __init__(self, flat: FlatGraph, dt: float, substeps: int,
                 signatures: dict[str, tuple] | None = None,
                 signer: Callable[[str, Block], tuple] | None = None) -> None:
        self.flat = flat
        self.dt = dt
        self.substeps = substeps
        self.eq_blocks = flat.equation_blocks()
        self.cs_blocks = flat.cosim_blocks()
        self.states, self.dstates, self.inputs, self.params, self.sig = (Layout() for _ in range(5))
        self.feed: dict[str, dict[str, Any]] = {}  # eq block path -> output port -> inputs it reads directly
        # each block's leaf signature (cpgsim.harness.compiler.kinds.leaf_signature): given, or made by ``signer``
        # (kinds.Signatures) in the pass over the blocks, or left to the kinds (None)
        self.signatures = signatures
        self._layouts(signer if signatures is None else None)

    def _layouts(self, signer: Callable[[str, Block], tuple] | None) -> None:
        """The slots of every equation block's states, discrete states, parameters and outputs (made when first
        read: :meth:`Layout.extend <cpgsim.harness.compiler.layout.Layout.extend>`), the start values and, with
        a ``signer``, every block's leaf signature (the cache key's and the kinds'). One pass over the blocks
        for all of it: a model of thousands of blocks does it on every compile, cached or not, and each block's
        tables are read while they are at hand (measured: a fifth less than a pass for the signatures and
        another for the layouts)."""
        signatures: dict[str, tuple] = {}
        # per layout: the declarations (frozen State, Parameter and Port objects) and each one's block path
        states, dstates, params, outputs = [], [], [], []  # type: ignore[var-annotated]
        st_at, ds_at, par_at, out_at = [], [], [], []  # type: ignore[var-annotated]
        p0: list = []
        for path, blk in self.eq_blocks.items():
            if signer is not None:
                signatures[path] = signer(path, blk)
            table = blk.states
            states.extend(table.values())
            st_at.extend(repeat(path, len(table)))
            table = blk.discrete_states
            if table:
                dstates.extend(table.values())
                ds_at.extend(repeat(path, len(table)))
            table = blk.parameters
            params.extend(table.values())
            par_at.extend(repeat(path, len(table)))
            p0.extend(map(blk.values.__getitem__, map(_NAME, table.values())))
            table = blk.outputs
            outputs.extend(table.values())
            out_at.extend(repeat(path, len(table)))
        if signer is not None:
            self.signatures = signatures
        self.states.extend(st_at, states)
        self.dstates.extend(ds_at, dstates)
        self.params.extend(par_at, params)
        self.sig.extend(out_at, outputs)
        x0 = list(chain.from_iterable(map(_START, states)))
        z0 = list(chain.from_iterable(map(_START, dstates)))
        for name, port in self.flat.inputs.items():
            self.inputs.add("$" + name, port.size, port.unit, port.kind, port.description)
        # co-simulation outputs that feed equation blocks are external inputs of the compiled part
        if self.cs_blocks:
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
