"""The co-simulation master: the macro-step loop over equation blocks and co-simulation blocks
(:mod:`.master`), what the master asks of a block beyond ``setup``/``do_step`` (:mod:`.contracts`:
ResumableBlock, FusedLoopBlock, the fused loop's request and status codes), and the fast path that runs a
block's own C loop with the compiled step (:mod:`.fused`)."""
