"""The engine that runs blocks: compile a graph to one CasADi step, loop it in C, co-simulate black boxes,
record results, cache compiled models, keep run folders. It imports only :mod:`cpgsim.components`; the
applications (:mod:`cpgsim.verify`, :mod:`cpgsim.experiments`, :mod:`cpgsim.cli`) sit above it, beside
:mod:`cpgsim.fmus` and :mod:`cpgsim.robots` (docs/architecture.md)."""

from cpgsim.components import moved

MOVED = {
    "cpgsim.harness.master": "cpgsim.harness.cosim.master",
    "cpgsim.harness.fused": "cpgsim.harness.cosim.fused",
    "cpgsim.harness.contracts": "cpgsim.harness.cosim.contracts (ResumableBlock, FusedLoopBlock)",
    "cpgsim.harness.toolchain": "cpgsim.harness.c.toolchain",
    "cpgsim.harness.exit_guard": "cpgsim.harness.c.exit_guard",
}
"""Modules of the engine's root before it was grouped into subpackages by role (2026-12), and where they went."""
moved.register(MOVED)
__getattr__ = moved.package_getattr(__name__)
