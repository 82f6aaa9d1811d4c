"""The C toolchain and the hand-written C it compiles: :mod:`.toolchain` (the compiler, flags, the library
cache, prototype tables), :mod:`.exit_guard` (native code that calls ``exit()`` or dies of a signal ends
cpgsim with one line), and the C sources beside them (horizon, function and batch drivers, the exit guard,
the fused loops' status codes)."""
