"""The robot as an FMU (experiments/plant_fmu.py, robots/mujoco/c/plant_fmu_core.h): a scenario's hexapod on its
terrain with MuJoCo inside, driven by fmpy alone.

The reference is cpgsim's own closed-loop run of the same scenario on MuJoCo: replaying the joint targets the run
recorded (one communication step of the run's 1 ms per row) must give the run's plant outputs. Both step the
same libmujoco with the same C (mujoco_step.h) and the same readout, so the expected difference is zero; the
issue's tolerance for the body path is 1e-4 m over 3 s, and the tests ask for bit equality."""

from __future__ import annotations

import os
import re
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

from cpgsim.cli.main import main as cli_main
from cpgsim.fmus.export.model_description import ExportError

T = 3.0
slow = pytest.mark.slow


def _run(scenario: str, sets: dict | None = None, t_end: float = T):
    """cpgsim's own run of ``scenario`` on MuJoCo: (results, the robot block's name, the targets it took)."""
    from cpgsim.experiments.runner import build_scenario
    from cpgsim.harness.simulate import Simulator

    setup = build_scenario(scenario, {**(sets or {}), "robot.engine": "mujoco"})
    source = next(str(src) for dst, src in setup.graph.connections.items() if str(dst) == f"{setup.robot}.q_target")
    record = [*(setup.record or []), f"{setup.robot}.*", source]
    res = Simulator(setup.graph, dt=1e-3, record=record).prepare().run(t_end)
    return res, setup.robot, res[source]


class Driver:
    """fmpy's low-level API on an exported plant FMU (FMI 2 or 3), with the importer's log kept."""

    def __init__(self, fmu, logged: list | None = None) -> None:
        from fmpy import extract, instantiate_fmu, read_model_description

        self.fmu = fmu
        self.md = read_model_description(fmu.path)
        self.dir = extract(fmu.path)
        self.log = [] if logged is None else logged
        self.inst = instantiate_fmu(self.dir, self.md, fmi_type="CoSimulation", debug_logging=False,
                                    logger=self._logger)
        self.vr_in = [fmu.vr(f"q_target[{i}]") for i in range(18)]
        self.outputs = [v.name for v in self.md.modelVariables if v.causality == "output" and v.type != "Boolean"]
        self.vr_out = [fmu.vr(n) for n in self.outputs]

    def _logger(self, *args) -> None:
        """fmpy's logger for FMI 2 (env, name, status, category, message) and 3 (no name): the message is last."""
        message = args[-1]
        self.log.append(message.decode() if isinstance(message, bytes) else str(message))

    def get(self, vrs):
        return self.inst.getReal(vrs) if self.fmu.fmi == 2 else self.inst.getFloat64(vrs)

    def set(self, vrs, values):
        return self.inst.setReal(vrs, values) if self.fmu.fmi == 2 else self.inst.setFloat64(vrs, values)

    def start(self, params: dict | None = None) -> None:
        if self.fmu.fmi == 2:
            self.inst.setupExperiment(startTime=0.0)
        for k, v in (params or {}).items():
            self.set([self.fmu.vr(k)], [v])
        if self.fmu.fmi == 2:
            self.inst.enterInitializationMode()
        else:
            self.inst.enterInitializationMode(startTime=0.0)
        self.inst.exitInitializationMode()

    def replay(self, times, targets, k0: int = 0) -> np.ndarray:
        """Rows of outputs at times[k0], ..., times[-1], stepping with targets[k] over [times[k], times[k+1]]."""
        rows = [self.get(self.vr_out)]
        for k in range(k0, len(times) - 1):
            self.set(self.vr_in, list(targets[k]))
            self.inst.doStep(currentCommunicationPoint=float(times[k]), communicationStepSize=1e-3)
            rows.append(self.get(self.vr_out))
        return np.array(rows)

    def reference(self, res, robot: str) -> np.ndarray:
        return np.column_stack([res[f"{robot}.{n}"] for n in self.outputs])

    def close(self) -> None:
        self.inst.terminate()
        self.inst.freeInstance()


@pytest.fixture(scope="module")
def step_run():
    return _run("step")


@pytest.fixture(scope="module", params=[2, 3])
def step_fmu(request, tmp_path_factory):
    from cpgsim.experiments.plant_fmu import export_plant_fmu

    return export_plant_fmu("step", tmp_path_factory.mktemp("plant") / f"plant{request.param}.fmu",
                            fmi=request.param)


@slow
def test_fmu_is_valid_for_fmpy_and_the_fmi_schema(step_fmu):
    """fmpy's validate_fmu (the FMI 2 / 3 XSD and its rules) finds nothing; the FMU declares Co-Simulation only,
    ports with units, no feedthrough (outputs depend on nothing the importer sets)."""
    from fmpy import read_model_description
    from fmpy.validation import validate_fmu

    assert validate_fmu(str(step_fmu.path)) == []
    md = read_model_description(step_fmu.path)
    assert md.coSimulation is not None and md.modelExchange is None
    ins = [v for v in md.modelVariables if v.causality == "input"]
    assert [v.name for v in ins] == [f"q_target[{i}]" for i in range(18)]
    assert {v.unit or (v.declaredType and v.declaredType.unit) for v in ins} == {"rad"}
    names = {v.name for v in md.modelVariables}
    assert {"q[17]", "qd[0]", "toe_force[17]", "body_position[2]", "body_rpy[0]", "foot_position[17]",
            "body_contact", "kp", "kd", "friction"} <= names
    assert all(not u.dependencies for u in md.outputs)
    assert md.defaultExperiment.stepSize == "0.001" or float(md.defaultExperiment.stepSize) == 1e-3
    with zipfile.ZipFile(step_fmu.path) as zf:
        members = zf.namelist()
    assert "resources/hexapod.xml" in members
    assert any(re.search(r"binaries/[^/]+/libmujoco\.so", m) for m in members)


@slow
def test_replaying_a_runs_targets_reproduces_its_outputs(step_fmu, step_run):
    """The FMU driven by fmpy with the targets cpgsim's run recorded gives every plant output of the run, bit
    for bit, over 3 s of the step scenario (the body path: within the issue's 1e-4 m a fortiori)."""
    res, robot, targets = step_run
    drv = Driver(step_fmu)
    drv.start()
    out = drv.replay(res.time, targets)
    ref = drv.reference(res, robot)
    drv.close()
    y = drv.outputs.index("body_position[1]")
    assert out[-1, y] - out[0, y] > 0.02  # the robot walked: the comparison is not of a robot standing still
    assert np.abs(out[:, y] - ref[:, y]).max() <= 1e-4
    assert np.array_equal(out, ref), f"max difference {np.abs(out - ref).max()}"


@slow
def test_tuned_parameters_equal_a_run_with_them(tmp_path):
    """kp, kd and friction set in the FMU (before initialization) give what a cpgsim run with those values
    gives: the set-up (settling included) and the steps use them as the plant does."""
    from cpgsim.experiments.plant_fmu import export_plant_fmu

    tuned = {"kp": 80.0, "kd": 1.5, "friction": 0.6}
    res, robot, targets = _run("step", {f"robot.{k}": v for k, v in tuned.items()}, t_end=1.0)
    fmu = export_plant_fmu("step", tmp_path / "plant.fmu", fmi=2)
    drv = Driver(fmu)
    drv.start(tuned)
    out = drv.replay(res.time, targets)
    assert np.array_equal(out, drv.reference(res, robot))
    drv.close()
    default = Driver(fmu)
    default.start()
    assert not np.array_equal(default.replay(res.time[:200], targets), out[:200])
    default.close()


@slow
def test_an_amputated_robot_replays_too(tmp_path):
    """The amputation scenario (legs whose shapes touch nothing, baked in at export) replays exactly too."""
    from cpgsim.experiments.plant_fmu import export_plant_fmu

    res, robot, targets = _run("fukuhara-amputation", t_end=1.5)
    fmu = export_plant_fmu("fukuhara-amputation", tmp_path / "amp.fmu", fmi=3)
    drv = Driver(fmu)
    drv.start()
    out = drv.replay(res.time, targets)
    assert np.array_equal(out, drv.reference(res, robot))
    drv.close()


@slow
def test_a_scenarios_pushes_are_tunable_parameters(tmp_path):
    """A scenario's push becomes parameters push[0].start_s, .duration_s, .force_N[0..2], .point_m[0..2]; the
    FMU replays the run with that push exactly, and with the force set otherwise it replays a run with that
    force exactly (the pushes are applied by the same C as cpgsim's MuJoCo step: mujoco_step.h)."""
    from cpgsim.experiments.plant_fmu import export_plant_fmu

    push = {"start_s": 0.5, "duration_s": 0.2, "force_N": [30.0, 0.0, 0.0], "point_m": [0.0, 0.05, 0.0]}
    fmu = export_plant_fmu("flat", tmp_path / "pushed.fmu", sets={"disturbance": [push]})
    names = [v.name for v in fmu.variables.of("parameter")]
    assert names[3:] == ["push[0].start_s", "push[0].duration_s", *(f"push[0].force_N[{j}]" for j in range(3)),
                         *(f"push[0].point_m[{j}]" for j in range(3))]
    outs = []
    for force in ([30.0, 0.0, 0.0], [-20.0, 10.0, 0.0]):
        res, robot, targets = _run("flat", {"disturbance": [{**push, "force_N": force}]}, t_end=1.2)
        drv = Driver(fmu)
        drv.start({f"push[0].force_N[{j}]": f for j, f in enumerate(force)})
        outs.append(drv.replay(res.time, targets))
        assert np.array_equal(outs[-1], drv.reference(res, robot))
        drv.close()
    y = Driver(fmu).outputs.index("body_position[0]")
    assert abs(outs[0][-1, y] - outs[1][-1, y]) > 0.01  # the push moved the robot


@slow
def test_fmu_state_get_set_and_serialize_replay_exactly(step_fmu, step_run):
    """An FMU state saved at 1 s and restored (also through serialize/deserialize) replays the next steps
    exactly; a reset instance replays the run from the start again."""
    res, robot, targets = step_run
    times = res.time[:1500]
    drv = Driver(step_fmu)
    drv.start()
    drv.replay(times[:1001], targets)
    inst = drv.inst
    state = inst.getFMUState() if step_fmu.fmi == 3 else inst.getFMUstate()
    first = drv.replay(times, targets, k0=1000)
    if step_fmu.fmi == 2:
        inst.setFMUstate(inst.deSerializeFMUstate(inst.serializeFMUstate(state)))
    else:
        inst.setFMUState(inst.deserializeFMUState(inst.serializeFMUState(state)))
    again = drv.replay(times, targets, k0=1000)
    assert np.array_equal(first, again)
    inst.reset()
    drv.start()
    assert np.array_equal(drv.replay(times[:1001], targets), drv.reference(res, robot)[:1001])
    drv.close()


@slow
def test_bad_calls_get_an_fmi_error_and_a_log_line(step_fmu):
    """A NaN input, a step that is not whole MuJoCo steps, a step from the wrong time, a parameter out of bounds
    or set after initialization: each is refused with an error status and one log line saying what."""
    from fmpy.fmi1 import FMICallException

    log: list[str] = []
    drv = Driver(step_fmu, log)
    with pytest.raises(FMICallException):
        drv.set([step_fmu.vr("kp")], [-1.0])
    assert "kp = -1 is out of bounds" in log[-1]
    drv.start()
    with pytest.raises(FMICallException):
        drv.set(drv.vr_in[:1], [float("nan")])
    assert "q_target[0]" in log[-1] and "not finite" in log[-1]
    with pytest.raises(FMICallException):
        drv.set(drv.vr_in[1:2], [1e12])
    assert "q_target[1] = 1e+12 rad is beyond MuJoCo's control limit" in log[-1]
    with pytest.raises(FMICallException):
        drv.set([step_fmu.vr("friction")], [0.5])
    assert "friction is fixed" in log[-1]
    with pytest.raises(FMICallException):
        drv.inst.doStep(currentCommunicationPoint=0.0, communicationStepSize=1.5e-3)
    assert "not a whole number of MuJoCo steps" in log[-1]
    with pytest.raises(FMICallException):
        drv.inst.doStep(currentCommunicationPoint=0.5, communicationStepSize=1e-3)
    assert "DoStep from t=0.5" in log[-1]
    drv.inst.doStep(currentCommunicationPoint=0.0, communicationStepSize=2e-3)  # still usable after refusals
    assert drv.get([step_fmu.vr("body_position[2]")])[0] > 0.05
    drv.close()


@slow
def test_the_binary_needs_only_the_fmus_folder_and_the_c_library(step_fmu, tmp_path):
    """ldd resolves every library of the FMU's binary inside the FMU's binaries folder or to the system's C
    library (libc, libm, libdl, libpthread, librt, the loader)."""
    if sys.platform != "linux":
        pytest.skip("ldd is Linux's")
    with zipfile.ZipFile(step_fmu.path) as zf:
        zf.extractall(tmp_path)
    binary = next((tmp_path / "binaries").glob(f"*/{step_fmu.model_identifier}.so"))
    out = subprocess.run(["ldd", str(binary)], capture_output=True, text=True, check=True,
                         env={**os.environ, "LD_LIBRARY_PATH": ""}).stdout
    assert "not found" not in out
    system = re.compile(r"^(libc|libm|libdl|libpthread|librt|ld-linux[-\w]*)\.so")
    for line in out.splitlines():
        name = line.split()[0]
        if "=>" not in line or name.startswith("linux-vdso"):
            continue
        where = Path(line.split("=>")[1].split()[0])
        assert where.parent == binary.parent or system.match(name), line


@slow
def test_the_fmu_runs_where_mujoco_is_not_installed(step_fmu, tmp_path):
    """A fresh virtual environment holding fmpy (and what fmpy needs) but not the mujoco package runs the FMU with
    fmpy's simulate_fmu; the libmujoco it maps is the one inside the FMU."""
    import fmpy

    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True)
    site = next((venv / "lib").glob("python3*/site-packages"))
    needed = ["fmpy", "numpy", "lxml", "attr", "attrs", "msgpack", "lark", "dask", "jinja2", "markupsafe"]
    deps = tmp_path / "deps"
    deps.mkdir()
    here = Path(fmpy.__file__).parent.parent
    for name in needed:
        if (here / name).exists():
            (deps / name).symlink_to(here / name)
    (site / "deps.pth").write_text(str(deps) + "\n")
    script = tmp_path / "run.py"
    script.write_text(
        "import sys\n"
        "from fmpy import simulate_fmu\n"
        "assert 'mujoco' not in sys.modules\n"
        "try:\n    import mujoco\nexcept ImportError:\n    pass\n"
        "else:\n    raise SystemExit('mujoco is importable here')\n"
        "maps = set()\n"
        "def mapped(time, recorder):  # while the FMU is loaded (fmpy unloads it at the end)\n"
        "    maps.update(ln.split()[-1] for ln in open('/proc/self/maps') if 'libmujoco' in ln)\n"
        "    return True\n"
        f"r = simulate_fmu({str(step_fmu.path)!r}, stop_time=0.05, output_interval=1e-3,\n"
        "                 output=['body_position[2]'], step_finished=mapped)\n"
        "print(r['body_position[2]'][-1], sorted(maps))\n")
    python = venv / "bin" / "python"
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "LD_LIBRARY_PATH", "VIRTUAL_ENV")}
    proc = subprocess.run([str(python), str(script)], capture_output=True, text=True, env=env, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-2000:]
    height, maps = proc.stdout.split(" ", 1)
    assert 0.05 < float(height) < 0.3
    assert "site-packages/mujoco" not in maps and "libmujoco" in maps


@slow
def test_no_leak_over_a_thousand_instances(step_fmu, tmp_path):
    """1,000 instantiate / initialize / step / terminate / free cycles in one process grow its resident memory by
    less than 20 MB (one instance's model and data are about 1 MB: a leak of one per cycle would be 1 GB)."""
    script = tmp_path / "cycles.py"
    script.write_text(
        "import resource, sys\n"
        "from fmpy import extract, instantiate_fmu, read_model_description\n"
        f"path = {str(step_fmu.path)!r}\n"
        "md = read_model_description(path)\nd = extract(path)\n"
        "def cycle():\n"
        "    inst = instantiate_fmu(d, md, fmi_type='CoSimulation')\n"
        + ("    inst.setupExperiment(startTime=0.0)\n    inst.enterInitializationMode()\n" if step_fmu.fmi == 2 else
           "    inst.enterInitializationMode(startTime=0.0)\n") +
        "    inst.exitInitializationMode()\n"
        "    inst.doStep(currentCommunicationPoint=0.0, communicationStepSize=1e-3)\n"
        "    inst.terminate()\n    inst.freeInstance()\n"
        "for _ in range(50):\n    cycle()\n"
        "before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss\n"
        "for _ in range(1000):\n    cycle()\n"
        "print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before)\n")
    proc = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert int(proc.stdout.strip()) < 20_000  # kB


def test_what_the_fmu_cannot_hold_is_refused_by_name(tmp_path, capsys):
    """Velocity feed-forward is refused naming the scenario key; the CLI needs --scenario and a Co-Simulation
    kind; nothing is written."""
    from cpgsim.experiments.plant_fmu import export_plant_fmu

    out = tmp_path / "plant.fmu"
    with pytest.raises(ExportError, match="velocity_ff"):
        export_plant_fmu("flat", out, sets={"robot.velocity_ff": True})
    with pytest.raises(ExportError, match="must end in .fmu"):
        export_plant_fmu("flat", tmp_path / "plant.zip")
    assert cli_main(["export", "plant", "-o", str(out)]) == 2
    assert "needs --scenario" in capsys.readouterr().err
    assert cli_main(["export", "plant", "--scenario", "flat", "--kind", "me", "-o", str(out)]) == 2
    assert "Co-Simulation only" in capsys.readouterr().err
    assert not out.exists()


def _libcosim_body(ssp: Path, seconds: float) -> np.ndarray:
    """The robot's body path from libcosim (the Open Simulation Platform's C++ master, through libcosimpy) running
    the SSP with its fixed-step algorithm at 1 ms: every slave steps, then outputs go to inputs (Jacobi)."""
    from fmpy import read_model_description
    from libcosimpy.CosimEnums import CosimVariableType
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    from libcosimpy.CosimObserver import CosimObserver

    log_output_level(CosimLogLevel.ERROR)
    ex = CosimExecution.from_ssp_file(ssp_path=str(ssp), step_size=1_000_000)
    robot = next(i.index for i in ex.slave_infos() if i.name == b"robot")
    with zipfile.ZipFile(ssp) as zf:
        md = read_model_description(zf.open("resources/robot.fmu"))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    n = int(round(seconds * 1000))
    obs = CosimObserver.create_time_series(buffer_size=n + 10)
    ex.add_observer(observer=obs)
    for i in range(3):
        obs.start_time_series(robot, vr[f"body_position[{i}]"], CosimVariableType.REAL)
    assert ex.simulate_until(target_time=n * 1_000_000)
    cols = []
    for i in range(3):
        times, _, values = obs.time_series_real_samples(robot, vr[f"body_position[{i}]"], from_step=0,
                                                        sample_count=n + 1)
        cols.append(values)
    assert np.array_equal(np.round(np.asarray(times) / 1e6), np.arange(len(times)))  # rows k = k ms
    return np.column_stack(cols)


@slow
def test_the_closed_loop_as_ssp_runs_as_the_native_loop(tmp_path, capsys):
    """`cpgsim export closed-loop` then `cpgsim simulate loop.ssp`: the controller FMU and the plant FMU under
    cpgsim's master end within 1 mm of the native closed loop after 5 s (the issue's criterion); in fact every
    row is bit-identical. Yu's controller declares no direct feedthrough (its targets depend on its states only),
    so another tool's master gives the same: libcosim runs the same SSP to the same rows."""
    from cpgsim.harness.results import Results

    loop, out = tmp_path / "loop.ssp", tmp_path / "loop.arrow"
    assert cli_main(["export", "closed-loop", "--scenario", "step", "-o", str(loop)]) == 0
    assert cli_main(["simulate", str(loop), "--t-end", "5", "-o", str(out)]) == 0
    capsys.readouterr()
    ssp = Results.load(out)
    native, robot, _ = _run("step", t_end=5.0)
    a, b = native[f"{robot}.body_position"], ssp[f"{robot}.body_position"]
    assert a.shape == b.shape == (5001, 3)
    assert np.abs(a - b).max() <= 1e-3
    assert np.array_equal(a, b)
    assert a[-1, 1] - a[0, 1] > 0.05  # it walked
    c = _libcosim_body(loop, 5.0)
    assert np.array_equal(c, a[:len(c)])


@slow
def test_with_feedthrough_the_masters_ordering_decides(tmp_path):
    """Fukuhara's controller reads the toe forces into its targets at the same instant (load-sensing limb modes:
    declared feedthrough). cpgsim's master sets the controller's inputs from the plant's outputs at t_k before
    reading its targets (Gauss-Seidel, plant first), as the native loop does: bit-identical over 3 s. libcosim's
    fixed-step master reads the controller's targets before its inputs move (Jacobi): it departs from the native
    loop within the first 10 ms."""
    from cpgsim.experiments.closed_loop import export_closed_loop
    from cpgsim.fmus.ssp import import_ssp
    from cpgsim.harness.simulate import Simulator

    loop = export_closed_loop("fukuhara-gaits", tmp_path / "loop.ssp")
    native, robot, _ = _run("fukuhara-gaits", t_end=3.0)
    ref = native[f"{robot}.body_position"]
    ours = Simulator(import_ssp(loop), dt=1e-3, record=[f"{robot}.body_position"]).prepare().run(3.0)
    assert np.array_equal(ours[f"{robot}.body_position"], ref)
    jacobi = _libcosim_body(loop, 3.0)
    differs = np.abs(jacobi - ref[:len(jacobi)]).max(axis=1) > 0
    assert differs.any() and int(np.argmax(differs)) <= 10


@slow
def test_a_mujoco_error_is_an_fmi_error_not_the_end_of_the_process(step_fmu, tmp_path):
    """MuJoCo's fatal errors end the process by default (its handler must not return). The FMU catches them
    while it steps MuJoCo and reports an FMI error with MuJoCo's message: here an FMU whose model was given too
    small a memory arena (edited in its resources) runs out of stack while settling; the importer (fmpy alone, no
    other MuJoCo user in the process) gets the error and goes on."""
    fmu = tmp_path / "small_arena.fmu"
    with zipfile.ZipFile(step_fmu.path) as zi, zipfile.ZipFile(fmu, "w") as zo:
        for item in zi.infolist():
            data = zi.read(item.filename)
            if item.filename == "resources/hexapod.xml":
                assert b'memory="4M"' in data
                data = data.replace(b'memory="4M"', b'memory="30K"')
            zo.writestr(item, data)
    script = tmp_path / "run.py"
    script.write_text(
        "import sys\n"
        "from fmpy import simulate_fmu\n"
        "log = []\n"
        "def logger(*args):\n    log.append(args[-1])\n"
        "try:\n"
        f"    simulate_fmu({str(fmu)!r}, stop_time=0.3, output_interval=1e-3, logger=logger)\n"
        "except Exception as exc:\n"
        "    print('FMI error', type(exc).__name__)\n"
        "print('messages', [m.decode() if isinstance(m, bytes) else str(m) for m in log][-1:])\n"
        "print('mujoco imported', 'mujoco' in sys.modules)\n")
    proc = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, cwd=tmp_path, timeout=120)
    assert proc.returncode == 0, proc.stdout + proc.stderr[-2000:]
    assert "FMI error" in proc.stdout
    assert "mj_stackAlloc: out of memory" in proc.stdout
    assert "mujoco imported False" in proc.stdout
