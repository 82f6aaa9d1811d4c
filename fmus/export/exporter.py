"""Native FMU export: any block or graph to an FMI 2.0 / 3.0 FMU that runs without Python.

>>> from cpgsim.components.library import single_vdp
>>> export_fmu(single_vdp(), "vdp.fmu", fmi=2, kind="both")            # doctest: +SKIP

The C code comes from the compiled model's CasADi functions (one source of truth: ``step`` for
Co-Simulation, ``ode``/``signals``/``discrete`` for Model Exchange, see :mod:`cpgsim.fmus.export.build`), wrapped by a
small hand-written FMI layer (``fmus/templates``). The binary links only libc and libm.

Semantics
---------
- **Co-Simulation** (FMI 2 and 3): internal fixed step ``dt`` (default 1 ms), exactly the sampled-step
  semantics of :class:`cpgsim.harness.simulate.Simulator`: each internal step applies the discrete updates and
  resets with the inputs held, then integrates with RK4 (``substeps`` per step). The communication step
  must be a multiple of ``dt``. Values read at a communication point are those after the sampled update
  at that point, computed with the inputs currently set, which is what the simulator records.
- **Model Exchange** (FMI 2 and 3): derivatives from ``ode``. The sampled discrete updates are **time
  events** at ``t0 + k*dt``: the FMU announces the next one through ``nextEventTime`` and applies the
  update (``discrete``) in ``fmi2NewDiscreteStates`` / ``fmi3UpdateDiscreteStates``, reporting
  ``valuesOfContinuousStatesChanged`` when a reset changed a continuous state. The first update happens
  in the event iteration right after initialization. Models whose update is the identity (no discrete
  states, no resets) announce no events at all. Step events were not chosen: they would make the
  update instants depend on the importer's integrator steps.
- **With clocks** (``clocks=True``, FMI 3): the sampled update runs at the ticks of the input clock ``sample``
  instead: in ME's event mode, and in CS's event mode (``hasEventMode``, instantiated with ``eventModeUsed``;
  ``fmi3DoStep`` then only integrates), see :mod:`cpgsim.fmus.export.clocks`.
- Parameters are ``causality="parameter" variability="fixed"``: settable after instantiation and in
  initialization mode (validated against their bounds, errors reported through the logger), not during
  the simulation. Continuous and discrete state start values can be set the same way. ``Reset`` restores
  every start value. FMU states can be saved, restored and serialized.

See :mod:`cpgsim.fmus.export.model_description` for variable names and value references.
"""

from __future__ import annotations

import shutil
import tempfile
from collections.abc import Mapping
from dataclasses import dataclass, field
from importlib import metadata
from pathlib import Path
from typing import Any

import casadi as ca

from cpgsim.components.core import Block
from cpgsim.components.graph import Graph
from cpgsim.fmus import trust
from cpgsim.fmus.export import build
from cpgsim.fmus.export.build import model_identifier
from cpgsim.fmus.export.model_description import ExportError, Variables, clock_vr, collect_variables, model_description
from cpgsim.harness.compile import compile_graph

KINDS = {"cs": ("cs",), "me": ("me",), "both": ("me", "cs")}


def _tool() -> str:
    try:
        version = metadata.version("cpgsim")
    except metadata.PackageNotFoundError:  # pragma: no cover - running from a checkout
        version = "dev"
    return f"cpgsim {version} (CasADi {ca.__version__})"


@dataclass
class FmuFile:
    """An FMU cpgsim wrote: the file, its variables (names, value references), identifiers."""

    path: Path
    variables: Variables = field(repr=False)
    model_identifier: str
    guid: str
    fmi: int

    def __fspath__(self) -> str:
        return str(self.path)

    def vr(self, name: str) -> int:
        """Value reference of the variable ``name``."""
        for v in self.variables.items:
            if v.name == name:
                return v.vr
        raise KeyError(name)


@dataclass
class ExportedFmu(FmuFile):
    """What :func:`export_fmu` wrote (an :class:`FmuFile`) and its interface kinds."""

    kinds: tuple[str, ...] = ()


def export_fmu(item: Graph | Block, path: str | Path, *, fmi: int = 2, kind: str = "both", dt: float = 1e-3,
               substeps: int = 1, params: Mapping[str, Any] | None = None, name: str | None = None,
               description: str | None = None, optimize: str | None = None,
               clocks: bool = False) -> ExportedFmu:
    """Export a block or graph as a native FMU at ``path``; returns an :class:`ExportedFmu`.

    ``fmi`` is 2 or 3; ``kind`` is ``"cs"`` (Co-Simulation), ``"me"`` (Model Exchange) or ``"both"``;
    ``dt`` the internal step and sample period, ``substeps`` the RK4 substeps per step (CS); ``params``
    overrides parameter defaults by path (globs allowed for graphs, as in ``Graph.set_param``); ``name``
    sets the model identifier (default: the graph's name); ``optimize`` the C compiler's optimization flag
    for the model code (default: ``-O2``, less for very large models, see
    :func:`cpgsim.fmus.export.build.auto_optimization`;
    the results do not depend on it); ``clocks``: the sampled blocks' discrete updates run at the ticks of
    an input clock ``sample`` (FMI 3; Co-Simulation with event mode, see :mod:`cpgsim.fmus.export.clocks`).
    Raises :class:`ExportError` (a
    :class:`~cpgsim.components.core.ModelError`) for anything that cannot be exported.
    """
    if fmi not in (2, 3):
        raise ExportError(f"FMI version must be 2 or 3, got {fmi!r}")
    if kind not in KINDS:
        raise ExportError(f"kind must be one of {', '.join(KINDS)}, got {kind!r}")
    path = Path(path)
    if path.suffix.lower() != ".fmu":
        raise ExportError(f"output {path} must end in .fmu")
    if params:
        if isinstance(item, Graph):
            for key, value in params.items():
                item.set_param(key, value)
        else:  # a single block: "param" or "<block>.param"
            item.set(**{k[len(item.name) + 1:] if k.startswith(item.name + ".") else k: v for k, v in params.items()})
    model = compile_graph(item, dt, substeps, grouping="flat")  # straight-line C, SX dependency analysis
    variables = collect_variables(model, fmi)
    if clocks:
        from cpgsim.fmus.export.clocks import check_clocked_export

        check_clocked_export(variables, fmi, kind, dt)
    identifier = model_identifier(name or model.name)
    kinds = KINDS[kind]
    desc = description or getattr(item, "description", "") or f"cpgsim model {model.name}"
    bin_folder, suffix = build.binary_dir(fmi)
    with tempfile.TemporaryDirectory(prefix="cpgsim-fmu-") as tmp:
        staging = Path(tmp) / "fmu"
        src = staging / "sources"
        src.mkdir(parents=True)
        names = build.functions_for(kinds, clocks)
        model_c = build.generate_model_sources(model, identifier, src, names)
        guid = build.fmu_guid(*model_c.values(), repr([(v.name, v.vr, v.kind, v.start) for v in variables.items]),
                     str(fmi), kind, repr(dt), repr(substeps), identifier, "clocks" if clocks else "")
        clock = clock_vr(variables) if clocks else None
        (src / "cpgsim_model.h").write_text(build.generate_header(variables, identifier, guid, kinds, names, clock))
        for f in ("cpgsim_core.h", *build.CORE_COMMON, f"fmi{fmi}.c"):
            shutil.copy(build.TEMPLATES / f, src / f)
        for h in build.fmi_headers(fmi):
            shutil.copy(h, src / h.name)
        sources = [f"fmi{fmi}.c", *model_c]
        (src / "CMakeLists.txt").write_text(build.cmake_lists(identifier, sources))
        if fmi == 3:
            (src / "buildDescription.xml").write_text(build.build_description(identifier, sources))
        xml = model_description(variables, fmi=fmi, identifier=identifier, guid=guid, kinds=kinds,
                                description=desc, sources=sources, dt=dt, tool=_tool(), clocks=clocks)
        (staging / "modelDescription.xml").write_bytes(xml)
        out_dir = staging / "binaries" / bin_folder
        out_dir.mkdir(parents=True)
        build.compile_binary(src, out_dir / f"{identifier}{suffix}", sources, optimize)
        trust.record_export(out_dir / f"{identifier}{suffix}", path)  # this user's own: may run in-process
        build.write_fmu(staging, path)
    return ExportedFmu(path, variables, identifier, guid, fmi, kinds)


def describe(item: Graph | Block, dt: float = 1e-3, fmi: int = 2) -> Variables:
    """The FMU variables ``item`` would export to (names, value references, start values)."""
    return collect_variables(compile_graph(item, dt, grouping="flat"), fmi)
