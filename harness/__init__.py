"""The engine that runs blocks: compile a graph to one CasADi step, loop it in C, co-simulate black boxes,
record results; subpackages `verify` (limit cycles), `experiments` (robot scenarios) and `cli` (`cpgsim`)."""
