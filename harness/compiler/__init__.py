"""The one compiler: a graph's wiring, sorted into a schedule of kinds, emitted as CasADi functions or C.

``wiring`` lays a flattened graph out in flat vectors (states, discrete states, inputs, parameters,
signals) and checks what the co-simulation blocks read; ``kinds`` derives each kind of identical instances'
equations once from the blocks' ``define``; ``schedule`` orders the instances' groups by signal level
(and evaluates them in straight-line form); ``casadi_form`` and ``c_form`` are the emitters: straight-line
SX functions (the flat compile: CasADi's VM, CasADi's own C for the native step and for FMUs, the
verifier's Jacobians), mapped MX functions and the looped C step (the grouped compile), where ``carry``
keeps a later pass from computing a costly subexpression again.
``cpgsim.harness.compile`` is the entry point (``compile_graph``, ``CompiledModel``)."""
