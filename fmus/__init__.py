"""The FMI bridge: `export` (native FMI 2/3 FMUs from a graph's CasADi functions, no Python inside),
`importer` (any FMU as a typed block, safely unpacked, optionally in a child process), `ssp` (system structure)."""
