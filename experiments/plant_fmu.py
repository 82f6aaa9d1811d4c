"""The robot as an FMU: a scenario's hexapod on its terrain, MuJoCo inside, as an FMI 2.0 / 3.0 Co-Simulation FMU.

>>> export_plant_fmu("step", "plant.fmu", fmi=2)                      # doctest: +SKIP

What the FMU holds (docs/fmu_export.md, "The robot as an FMU"):

- ``resources/hexapod.xml``: the MJCF of :meth:`cpgsim.robots.mujoco.plant.MujocoHexapod.xml` (robot and
  terrain, the scenario's contact model);
- ``binaries/<platform>/<id>.so``: the FMI layer of every cpgsim FMU (``fmus/export/templates/fmi2.c``,
  ``fmi3.c``) on the plant's core ``robots/mujoco/c/plant_fmu_core.h``, which steps MuJoCo with
  ``robots/mujoco/c/mujoco_step.h`` -- the C cpgsim's own MuJoCo plant runs -- and reads the outputs with the
  plant's readout (:mod:`cpgsim.robots.readout`, CasADi-generated C); beside it the ``libmujoco`` of the
  installed ``mujoco`` package, found through ``$ORIGIN``: the FMU needs neither Python nor MuJoCo installed;
- ``sources/``: every C file above plus ``CMakeLists.txt`` (a rebuild needs MuJoCo's headers and library, so
  ``modelDescription.xml`` lists no source files for importers to compile alone).

Variables: the plant block's ports with their names, units and sizes (``q_target[0..17]`` in, ``q``, ``qd``,
``toe_force``, ``body_position``, ``body_rpy``, ``foot_position``, ``body_contact`` out, no direct
feedthrough) and the parameters that need no rebuild: ``kp``, ``kd``, ``friction`` and each of the scenario's
pushes (``push[i].start_s``, ``.duration_s``, ``.force_N[0..2]``, ``.point_m[0..2]``), fixed after
initialization. Baked in at export: the terrain, the contact model and MuJoCo step, the robot's geometry,
start posture and placement, the settle time, amputated legs, the number of pushes. Not exported:
``velocity_ff``, refused by name.

Driving the FMU with the joint targets a cpgsim run recorded, one communication step of the run's ``dt`` per
row, reproduces the run's plant outputs bit for bit (tests/test_plant_fmu.py).
"""

from __future__ import annotations

import hashlib
import shutil
import tempfile
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from cpgsim.fmus import trust
from cpgsim.fmus.export import build
from cpgsim.fmus.export.exporter import FmuFile
from cpgsim.fmus.export.model_description import ExportError, Variable, Variables, model_description
from cpgsim.robots.description import describe_hexapod
from cpgsim.robots.ports import OUTPUT_PORTS

MJCF_NAME = "hexapod.xml"
CORE_NAME = "cpgsim_mujoco_plant.h"
PARAMETERS = ("kp", "kd", "friction")
"""The plant's parameters the FMU exports (tunable until initialization ends)."""
DT = 1e-3
"""The co-simulation step of a scenario run (experiments/runner.py): the default experiment's step."""


@dataclass
class PlantFmu(FmuFile):
    """What :func:`export_plant_fmu` wrote (an :class:`~cpgsim.fmus.export.exporter.FmuFile`): the scenario, its
    default end time and the MuJoCo step baked in."""

    scenario: str = ""
    t_end: float = 0.0
    time_step: float = 0.0


def export_plant_fmu(scenario: str | Path, path: str | Path, *, fmi: int = 2,
                     sets: Mapping[str, Any] | None = None, name: str | None = None) -> PlantFmu:
    """Export the robot of ``scenario`` (a built-in name or a ``.toml`` file, with ``--set``-style ``sets``) on
    its terrain as a Co-Simulation FMU at ``path`` (FMI ``fmi`` 2 or 3), MuJoCo inside whatever the
    scenario's ``robot.engine``. Raises :class:`~cpgsim.fmus.export.model_description.ExportError` for what
    the FMU cannot hold (``velocity_ff``) or cannot be built (no compiler, no libmujoco)."""
    from cpgsim.experiments.runner import build_scenario

    _check_target(path, fmi)
    return export_setup_plant(build_scenario(scenario, {**(sets or {}), "robot.engine": "mujoco"}), path,
                              fmi=fmi, name=name, label=str(scenario))


def _check_target(path: str | Path, fmi: int) -> None:
    if fmi not in (2, 3):
        raise ExportError(f"FMI version must be 2 or 3, got {fmi!r}")
    if Path(path).suffix.lower() != ".fmu":
        raise ExportError(f"output {path} must end in .fmu")


def export_setup_plant(setup, path: str | Path, *, fmi: int = 2, name: str | None = None,
                       label: str | None = None) -> PlantFmu:
    """The plant FMU of a built scenario (:class:`~cpgsim.experiments.setup.RunSetup` on MuJoCo), as
    :func:`export_plant_fmu`."""
    _check_target(path, fmi)
    path = Path(path)
    plant = setup.graph.blocks[setup.robot]
    if getattr(plant, "engine", None) != "mujoco":
        raise ExportError(f"the plant FMU holds a MuJoCo robot; this scenario's robot runs on "
                          f"{getattr(plant, 'engine', type(plant).__name__)!r} (set robot.engine = \"mujoco\")")
    label = setup.scenario.name if setup.scenario is not None else (label or setup.graph.name)
    if plant.values["velocity_ff"]:
        raise ExportError(f"scenario {label}: the plant FMU does not feed the target velocity forward "
                          "(robot.velocity_ff = true)")
    if plant.ankle is not None:
        raise ExportError(f"scenario {label}: the plant FMU has rigid feet; a compliant ankle ([robot.ankle]) "
                          "is not exported")
    identifier = build.model_identifier(name or f"hexapod_{label}")
    with tempfile.TemporaryDirectory(prefix="cpgsim-plant-fmu-") as tmp:
        staging = Path(tmp) / "fmu"
        guid, variables = _stage(plant, staging, identifier, fmi, label, setup.t_end, path)
        build.write_fmu(staging, path)
    return PlantFmu(path, variables, identifier, guid, fmi, label, float(setup.t_end), plant.time_step)


def _stage(plant, staging: Path, identifier: str, fmi: int, label: str, t_end: float,
           path: Path) -> tuple[str, Variables]:
    """Write the FMU's files into ``staging``; ``(guid, variables)``."""
    facts = _facts(plant)
    src, res = staging / "sources", staging / "resources"
    src.mkdir(parents=True)
    res.mkdir()
    (res / MJCF_NAME).write_text(facts.xml)
    variables = plant_variables(plant, fmi, f"hexapod on {label}")
    readout = build.casadi_source(_readout(plant, identifier), "cpgsim_readout.c", src, "the plant's readout")
    (src / CORE_NAME).write_text(facts.core)
    guid = build.fmu_guid(facts.xml, readout, facts.core, repr([(v.name, v.vr, v.start) for v in variables.items]),
                          str(fmi), facts.version)
    (src / "cpgsim_model.h").write_text(plant_header(plant, facts, variables, identifier, guid, fmi))
    for f in (*build.CORE_COMMON, f"fmi{fmi}.c"):
        shutil.copy(build.TEMPLATES / f, src / f)
    for h in build.fmi_headers(fmi):
        shutil.copy(h, src / h.name)
    sources = [f"fmi{fmi}.c", "cpgsim_readout.c"]
    (src / "CMakeLists.txt").write_text(cmake_lists(identifier, sources, facts.library.name))
    xml_md = model_description(variables, fmi=fmi, identifier=identifier, guid=guid, kinds=("cs",),
                               description=f"cpgsim hexapod plant (MuJoCo {facts.version}) of scenario {label}",
                               sources=[], dt=DT, tool=f"cpgsim (MuJoCo {facts.version})",
                               internal_dt=plant.time_step, stop_time=t_end)
    (staging / "modelDescription.xml").write_bytes(xml_md)
    bin_folder, suffix = build.binary_dir(fmi)
    out_dir = staging / "binaries" / bin_folder
    out_dir.mkdir(parents=True)
    bundled = out_dir / facts.library.name
    shutil.copy(facts.library, bundled)
    binary = out_dir / f"{identifier}{suffix}"
    build.compile_binary(src, binary, sources, include_dirs=(facts.include,),
                         link_args=("-Wl,--no-as-needed", str(bundled), "-Wl,-rpath,$ORIGIN"))
    trust.record_export(binary, path)  # this user's own: may run in-process
    return guid, variables


def _facts(plant):
    """The MuJoCo side (:mod:`cpgsim.robots.mujoco.fmu_facts`), its failures as export errors."""
    from cpgsim.components.core import ModelError
    from cpgsim.harness.c.toolchain import NativeUnavailable
    from cpgsim.robots.mujoco.fmu_facts import plant_fmu_facts  # the scenario's plant is a MujocoHexapod

    try:
        return plant_fmu_facts(plant)
    except (NativeUnavailable, ModelError) as exc:
        raise ExportError(f"cannot build the plant FMU: {exc}") from None


def _readout(plant, identifier: str):
    """The plant's compiled readout (the MuJoCo layout), named for this FMU."""
    import casadi as ca

    from cpgsim.robots.plant_base import readout_for

    fn = readout_for(plant.geometry, plant.READOUT_ROOT)
    return ca.Function(f"{identifier}_readout", fn.sx_in(), fn.call(fn.sx_in()), fn.name_in(), fn.name_out())


@dataclass(frozen=True)
class PlantParameter:
    """One tunable parameter of the plant FMU: its start value, unit, bounds (``strict``: exclusive)."""

    name: str
    value: float
    unit: str
    lo: float
    hi: float
    strict: bool
    description: str


def plant_parameters(plant) -> list[PlantParameter]:
    """The FMU's parameters, in the order ``plant_fmu_core.h`` reads them: ``kp``, ``kd``, ``friction``, then per
    push of the scenario ``push[i].start_s``, ``.duration_s``, ``.force_N[0..2]``, ``.point_m[0..2]``
    (C's ``cpgsim_push`` layout; the bounds of :mod:`cpgsim.robots.disturbance` per component)."""
    from cpgsim.robots.disturbance import MAX_FORCE_N, MAX_POINT_M

    out = []
    for pname in PARAMETERS:
        par = plant.parameters[pname]
        lo, hi = par.bounds
        rule = f"> {lo:g}" if not np.isfinite(hi) else f"strictly between {lo:g} and {hi:g}"
        out.append(PlantParameter(pname, float(plant.values[pname]), par.unit, lo, hi, True,
                                  f"{par.description} (must be {rule})"))
    for i, push in enumerate(plant.pushes):
        head = f"push[{i}]"
        out.append(PlantParameter(f"{head}.start_s", push.start_s, "s", 0.0, np.inf, False,
                                  "the push starts (steps starting from here, less half a step, feel it)"))
        out.append(PlantParameter(f"{head}.duration_s", push.duration_s, "s", 0.0, np.inf, True,
                                  "how long the push lasts (must be > 0)"))
        for j, f in enumerate(push.force_N):
            out.append(PlantParameter(f"{head}.force_N[{j}]", f, "N", -MAX_FORCE_N, MAX_FORCE_N, False,
                                      "push force, world frame"))
        for j, q in enumerate(push.point_m):
            out.append(PlantParameter(f"{head}.point_m[{j}]", q, "m", -MAX_POINT_M, MAX_POINT_M, False,
                                      "where the push acts, body frame"))
    return out


def plant_variables(plant, fmi: int, name: str) -> Variables:
    """The FMU's variables: ``q_target[i]`` (inputs), the output ports element by element, the parameters; value
    references dense in that order after FMI 3's ``time`` (the order ``plant_fmu_core.h`` decodes)."""
    items: list[Variable] = []
    port = plant.inputs["q_target"]
    for i in range(port.size):
        items.append(Variable(f"q_target[{i}]", "input", i, "real", "input", "continuous", None, float(plant.q0[i]),
                              port.unit, port.description))
    k = 0
    for pname, size in OUTPUT_PORTS:
        out = plant.outputs[pname]
        names = [pname] if size == 1 else [f"{pname}[{i}]" for i in range(size)]
        for el in names:
            items.append(Variable(el, "output", k, out.kind, "output",
                                  "continuous" if out.kind == "real" else "discrete", "calculated", None, out.unit,
                                  out.description))
            k += 1
    for i, par in enumerate(plant_parameters(plant)):
        items.append(Variable(par.name, "parameter", i, "real", "parameter", "fixed", "exact", par.value, par.unit,
                              par.description, None if par.strict or not np.isfinite(par.lo) else par.lo,
                              None if par.strict or not np.isfinite(par.hi) else par.hi))
    first = 1 if fmi == 3 else 0
    for k, v in enumerate(items):
        v.vr = first + k
    return Variables(items, None, False, name)


def plant_header(plant, facts, variables: Variables, identifier: str, guid: str, fmi: int) -> str:
    """``cpgsim_model.h`` of a plant FMU: what ``plant_fmu_core.h`` reads (sizes, start values, names, the
    placed robot, the shapes' contact codes, the readout function); ``facts`` the MuJoCo side."""
    c = build
    outputs = variables.of("output")
    shapes = describe_hexapod(plant.geometry).shapes()
    params = plant_parameters(plant)
    tag = int(hashlib.sha256(guid.encode()).hexdigest()[:12], 16)
    settle = int(round(plant.settle / plant.time_step))
    fn = f"{identifier}_readout"
    lines = [
        f"/* Generated by cpgsim for the plant FMU {identifier}: sizes, start values and tables. Do not edit. */",
        "#ifndef CPGSIM_MODEL_H", "#define CPGSIM_MODEL_H", "#include <math.h>", "",
        f"#define CPG_CORE_HEADER {c.c_string(CORE_NAME)}  /* the core the FMI layer runs on */",
        f"#define CPG_MODEL_NAME {c.c_string(variables.name)}",
        f"#define CPG_GUID {c.c_string(guid)}",
        f"#define CPG_STATE_TAG {float(tag)!r}",
        "#define CPG_HAS_ME 0", "#define CPG_HAS_CS 1", "#define CPG_CLOCKED 0", "#define CPG_CLOCK_VR -1",
        "#define CPG_NX 0",
        f"#define CPG_DT {plant.time_step!r}",
        f"#define CPG_VR_FIRST {1 if fmi == 3 else 0}u",
        f"#define CPG_NU {len(variables.of('input'))}", f"#define CPG_NOUT {len(outputs)}",
        f"#define CPG_NP {len(params)}", f"#define CPG_NPUSH {len(plant.pushes)}",
        f"#define CPG_MJCF_NAME {c.c_string(MJCF_NAME)}",
        f"#define CPG_MJ_VERSION {facts.mj_version}",
        f"#define CPG_MJ_STATE_SIZE {facts.state_size}",
        f"#define CPG_SETTLE_STEPS {settle}",
        f"#define CPG_TERRAIN_FRICTION {float(plant.terrain.friction)!r}",
        f"#define CPG_NSHAPES {len(shapes)}",
        f"int {fn}(const double** arg, double** res, long long int* iw, double* w, int mem);",
        f"int {fn}_work(long long int* sz_arg, long long int* sz_res, long long int* sz_iw, long long int* sz_w);",
        f"#define CPG_FN_READOUT {fn}", f"#define CPG_FN_READOUT_WORK {fn}_work", "",
        f"static const double CPG_U0[] = {c.c_doubles([v.start for v in variables.of('input')])};",
        f"static const double CPG_Q0[] = {c.c_doubles(plant.q0)};",
        f"static const double CPG_P0[] = {c.c_doubles([p.value for p in params])};",
        f"static const double CPG_P_LO[] = {c.c_doubles([p.lo for p in params])};",
        f"static const double CPG_P_HI[] = {c.c_doubles([p.hi for p in params])};",
        f"static const char CPG_P_STRICT[] = {c.c_string(''.join('01'[p.strict] for p in params))};",
        f"static const double CPG_QPOS0[] = {c.c_doubles(plant.initial_qpos())};",
        f"static const char CPG_OUT_KIND[] = {c.c_string(''.join('rb'[v.kind == 'boolean'] for v in outputs))};",
        f"static const char *const CPG_U_NAME[] = {c.c_strings([v.name for v in variables.of('input')])};",
        f"static const char *const CPG_OUT_NAME[] = {c.c_strings([v.name for v in outputs])};",
        f"static const char *const CPG_P_NAME[] = {c.c_strings([p.name for p in params])};",
        f"static const char *const CPG_SHAPE_NAME[] = {c.c_strings([s.name for s in shapes])};",
        f"static const int CPG_SHAPE_CODE[] = {{{', '.join(str(s.contact_code(plant.sense_shank)) for s in shapes)}}};",
        f"static const int CPG_SHAPE_OFF[] = {{{', '.join(str(int(s.leg in plant.amputated)) for s in shapes)}}};",
        "", "#endif", ""]
    return "\n".join(lines)


def cmake_lists(identifier: str, sources: list[str], libmujoco: str) -> str:
    """A build description for another platform: needs MuJoCo's headers and library (``MUJOCO_DIR``)."""
    return f"""# Build the plant FMU's binary from these sources (needs MuJoCo: its include/ and library):
#   cmake -S . -B build -DMUJOCO_DIR=/path/to/mujoco && cmake --build build --config Release
# then copy the library (named {identifier}.so/.dll/.dylib) and MuJoCo's library ({libmujoco} here) into
# binaries/<platform>/ of the FMU; the binary finds MuJoCo's library beside itself.
cmake_minimum_required(VERSION 3.10)
project({identifier} C)
set(MUJOCO_DIR "" CACHE PATH "MuJoCo's folder (include/, lib/)")
find_library(MUJOCO_LIB NAMES mujoco PATHS ${{MUJOCO_DIR}} ${{MUJOCO_DIR}}/lib REQUIRED)
add_library({identifier} SHARED {" ".join(sources)})
target_include_directories({identifier} PRIVATE ${{CMAKE_CURRENT_SOURCE_DIR}} ${{MUJOCO_DIR}}/include)
target_link_libraries({identifier} ${{MUJOCO_LIB}})
set_target_properties({identifier} PROPERTIES PREFIX "" C_VISIBILITY_PRESET hidden BUILD_RPATH "$ORIGIN"
                      INSTALL_RPATH "$ORIGIN")
if(UNIX)
  target_link_libraries({identifier} m)
endif()
"""
