"""The engine that runs blocks: compile a graph to one CasADi step, loop it in C, co-simulate black boxes,
record results, cache compiled models, keep run folders. It imports only :mod:`cpgsim.components`; the
applications (:mod:`cpgsim.verify`, :mod:`cpgsim.experiments`, :mod:`cpgsim.cli`) sit above it, beside
:mod:`cpgsim.fmus` and :mod:`cpgsim.robots` (docs/architecture.md)."""
