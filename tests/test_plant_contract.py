"""The hexapod plant contract (issue 57), checked the same way on every registered engine: the same ports,
a standing robot carries its weight, the C step equals the Python step bit for bit, a snapshot restored
replays the next steps exactly, and a capability an engine does not declare is refused naming it.

An engine whose Python package is missing is skipped by name. Expected values come from outside the plants:
the port table of docs (robots/ports.py's docstring, written out below), the robot's masses from the neutral
description times g."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from cpgsim.components.core import ParameterError
from cpgsim.components.geometry import YU_SIM
from cpgsim.harness.cosim.contracts import FusedLoopBlock, ResumableBlock
from cpgsim.robots.description import describe_hexapod, standing_posture
from cpgsim.robots.registry import CAPABILITIES, ENGINES, make_plant, require

sys.path.insert(0, str(Path(__file__).resolve().parent))
import point_feet_engine  # noqa: E402

G = 9.81  # m/s^2
DT = 1e-3
UNDER_TEST = {**ENGINES, point_feet_engine.ENGINE.name: point_feet_engine.ENGINE}
"""The registered engines and a stand-in third one (tests/point_feet_engine.py: a class and a registry line)."""


@pytest.fixture(autouse=True)
def _third_engine(monkeypatch):
    """The stand-in engine is in the registry while these tests run, and only then."""
    monkeypatch.setitem(ENGINES, point_feet_engine.ENGINE.name, point_feet_engine.ENGINE)


def _engines(*needs: str) -> list:
    """Every engine under test (those declaring ``needs``), skipped by name when its package is missing."""
    params = []
    for name, eng in UNDER_TEST.items():
        if not all(n in eng.capabilities or n in eng.options for n in needs):
            continue
        params.append(pytest.param(name, id=name, marks=pytest.mark.skipif(
            not eng.available(), reason=f"engine {name!r} needs the {eng.package} package ({eng.install})")))
    return params


# the plant's ports as documented (name, direction, shape, unit, kind): every engine declares exactly these
PORTS = {
    ("q_target", "in", (18,), "rad", "real"),
    ("q", "out", (18,), "rad", "real"),
    ("qd", "out", (18,), "rad/s", "real"),
    ("toe_force", "out", (18,), "N", "real"),
    ("body_position", "out", (3,), "m", "real"),
    ("body_rpy", "out", (3,), "rad", "real"),
    ("foot_position", "out", (18,), "m", "real"),
    ("body_contact", "out", (1,), "1", "boolean"),
}


def _ports(plant) -> set[tuple]:
    return {(p.name, p.direction, tuple(p.shape), p.unit, p.kind)
            for p in [*plant.inputs.values(), *plant.outputs.values()]}


@pytest.mark.parametrize("engine", _engines())
def test_ports_are_the_documented_ones(engine):
    plant = make_plant(engine)
    assert _ports(plant) == PORTS
    plant.setup(0.0)
    out = plant.get_outputs()
    assert {k: v.shape for k, v in out.items()} == {name: shape for name, d, shape, _, _ in PORTS if d == "out"}
    plant.terminate()


def test_every_engine_has_the_same_ports_and_parameters():
    available = [name for name, eng in ENGINES.items() if eng.available()]
    if len(available) < 2:
        pytest.skip(f"only {available} installed: nothing to compare")
    plants = [make_plant(name) for name in available]
    ref = plants[0]
    for other in plants[1:]:
        assert _ports(other) == _ports(ref), other.engine
        assert {k: repr(v) for k, v in other.parameters.items()} == {k: repr(v) for k, v in ref.parameters.items()}


@pytest.mark.parametrize("engine", _engines())
def test_a_standing_robot_carries_its_weight(engine):
    weight = sum(m.mass for m in describe_hexapod(YU_SIM).mass_properties().values()) * G
    plant = make_plant(engine, geometry=YU_SIM, settle=0.5)
    plant.setup(0.0)
    for _ in range(200):
        plant.set_inputs({"q_target": plant.q0})
        plant.do_step(plant.time, DT)
    fz = plant.toe_force_world()[:, 2]
    assert fz.sum() == pytest.approx(weight, rel=1e-3)  # issue 57 asks 2 %; docs/engines.md states 0.1 %
    assert np.all(fz > 0.1 * weight / 6), fz  # every foot stands
    assert np.abs(plant.toe_force_world()[:, :2]).max() < 0.05 * weight  # no sliding
    out = plant.get_outputs()
    assert out["toe_force"].reshape(6, 3)[:, 2].sum() == pytest.approx(weight, rel=1e-3)  # body frame, level
    np.testing.assert_allclose(out["q"], standing_posture(YU_SIM), atol=0.03)
    assert np.abs(out["body_rpy"]).max() < 1e-3
    assert not plant.fell() and out["body_contact"][0] == 0.0
    plant.terminate()


def _walk(plant, steps: int) -> np.ndarray:
    """Targets swinging by 0.3 rad around the standing posture (feet lift and land, contacts come and go);
    every output after every step. The targets depend on the plant's clock only."""
    rows = []
    for _ in range(steps):
        k = round(plant.time / DT)
        plant.set_inputs({"q_target": plant.q0 + 0.3 * np.sin(2 * np.pi * k / 400.0 + np.arange(18))})
        plant.do_step(plant.time, DT)
        rows.append(np.concatenate([v.ravel() for v in plant.get_outputs().values()]))
    return np.array(rows)


PUSHES = [{"start_s": 0.3, "duration_s": 0.2, "force_N": [25.0, -10.0, 5.0], "point_m": [0.05, 0.1, 0.02]},
          {"start_s": 0.4, "duration_s": 0.0105, "force_N": [0.0, 40.0, 0.0]}]
"""Two pushes during a walk, overlapping, one off the body's origin, one not a whole number of steps long."""


@pytest.mark.parametrize("pushes", [(), PUSHES], ids=["no push", "pushes"])
@pytest.mark.parametrize("engine", _engines("native"))
def test_the_c_step_equals_the_python_step(engine, pushes):
    """``native=`` is a constructor argument of every engine that offers the choice; over 2 s of moving
    targets the two give the same outputs bit for bit, with pushes too (MuJoCo's C step applies them with the
    same sums as the Python step: mujoco_step.h's cpgsim_push_wrench; DART's takes its push steps in Python)."""
    if pushes and "pushes" not in UNDER_TEST[engine].capabilities:
        pytest.skip(f"engine {engine!r} takes no pushes")
    runs = {}
    for native in (False, True):
        plant = make_plant(engine, settle=0.1, native=native, disturbances=list(pushes))
        plant.setup(0.0)
        if native and plant.native_step is None:
            pytest.skip(f"engine {engine!r}: no C step here (no C compiler or no engine library symbols)")
        assert (plant.native_step is not None) == native
        runs[native] = _walk(plant, 2000)
        assert (plant.native_step is not None) == native  # the C step was not dropped on the way
        plant.terminate()
    np.testing.assert_array_equal(runs[True], runs[False])
    assert np.ptp(runs[False][:, :18], axis=0).min() > 0.1  # every joint moved


@pytest.mark.parametrize("engine", _engines("snapshot_restore"))
def test_a_restored_snapshot_replays_the_next_steps_exactly(engine):
    plant = make_plant(engine, settle=0.1)
    assert isinstance(plant, ResumableBlock)
    plant.setup(0.0)
    _walk(plant, 200)
    snap = plant.snapshot()
    ahead = _walk(plant, 2000)  # the next 2 s
    plant.restore(snap)
    assert plant.time == pytest.approx(0.2)
    np.testing.assert_array_equal(_walk(plant, 2000), ahead)
    plant.terminate()

    resumed = make_plant(engine, settle=0.1)  # a new plant that starts its run in the saved state
    resumed.resume_from(snap)
    resumed.setup(snap.t)
    np.testing.assert_array_equal(_walk(resumed, 2000), ahead)
    resumed.terminate()
    assert resumed.last_snapshot is not None and resumed.last_snapshot.t == pytest.approx(2.2)


@pytest.mark.parametrize("engine", _engines())
def test_a_capability_not_declared_is_refused_by_name(engine):
    declared = ENGINES[engine].capabilities
    plant = make_plant(engine)
    assert isinstance(plant, ResumableBlock) == ("snapshot_restore" in declared)
    assert isinstance(plant, FusedLoopBlock) == ("fused_loop" in declared)
    for capability in CAPABILITIES:
        if capability in declared:
            assert require(engine, capability, "a test").name == engine
            continue
        with pytest.raises(ParameterError, match=rf"a test needs the {capability.replace('_', ' ')} capability, "
                                                 rf"which engine '{engine}' does not have") as err:
            require(engine, capability, "a test")
        assert "\n" not in str(err.value)
    for other in ENGINES.values():
        for option in other.options:
            if option in ENGINES[engine].options:
                continue
            with pytest.raises(ParameterError, match=rf"{option} \(an option of engine '([\w-]+)'\) applies to "
                                                     rf"engine '\1', not '{engine}'") as err:
                make_plant(engine, **{option: "x"})
            assert option in ENGINES[err.value.args[0].split("'")[1]].options  # the engine named has it


def test_an_unknown_capability_is_refused_by_name():
    with pytest.raises(ParameterError, match="unknown engine capability 'teleport'"):
        ENGINES["dart"].supports("teleport")


@pytest.mark.parametrize("engine", _engines("fused_loop", "native"))
def test_the_fused_native_and_python_paths_record_the_same_walk(engine, monkeypatch):
    """The ``step`` scenario's closed loop three ways: controller and plant in one C loop (the master's fast
    path), the Python master with the plant's C step, and the Python master with the plant's Python step.
    They record the same numbers bit for bit over 2.05 s (chunk boundaries inside, a partial last chunk)."""
    import cpgsim.harness.cosim.fused as fused
    from cpgsim.experiments.runner import build_scenario
    from cpgsim.harness.simulate import Simulator

    runs, used, stepped = {}, {}, {}
    original = fused.fused_runner
    for path, native, allow in (("fused", True, True), ("native", True, False), ("python", False, False)):
        def runner(*args, path=path, allow=allow):
            r = original(*args) if allow else None
            used[path] = r is not None
            return r

        monkeypatch.setattr(fused, "fused_runner", runner)
        setup = build_scenario("step", {"robot.engine": engine})
        robot = setup.graph.blocks[setup.robot]
        robot.native = native
        stepped[path] = False

        def terminate(robot=robot, path=path, original=robot.terminate):  # did a C step run? (dropped here)
            stepped[path] |= robot.native_step is not None
            original()
        robot.terminate = terminate
        sim = Simulator(setup.graph, dt=DT, record=setup.record, step_thread=False).prepare()
        runs[path] = sim.run(2.05)
    if not used["fused"]:
        pytest.skip(f"engine {engine!r}: no fused loop here (no C compiler or no C step)")
    assert used == {"fused": True, "native": False, "python": False}
    assert stepped == {"fused": True, "native": True, "python": False}
    ref = runs["python"]
    assert len(ref.time) == 2051
    for path in ("fused", "native"):
        assert runs[path].columns == ref.columns
        np.testing.assert_array_equal(runs[path].data, ref.data, err_msg=path)
    assert np.abs(ref["robot.toe_force"]).max() > 1.0  # walking: forces recorded


def _mass() -> float:
    return sum(m.mass for m in describe_hexapod(YU_SIM).mass_properties().values())


@pytest.mark.parametrize("engine", _engines("pushes"))
def test_a_push_moves_the_flying_robot_by_its_impulse(engine):
    """A 20 N push for 0.1 s on the robot in the air (no contact, servos holding the posture): the robot's
    centre of mass moves ``F T (t - T/2) / m`` along the push by ``t`` = 0.2 s (8.29 cm; the body frame's
    origin sits above the centre of mass, so the push also pitches the body a little and the origin moves
    1 % more: 2 % allowed), and falls ``g t^2 / 2``; no other direction moves."""
    force, duration, t = 20.0, 0.1, 0.2
    plant = make_plant(engine, body_height=1.0, disturbances=[
        {"start_s": 0.0, "duration_s": duration, "force_N": [force, 0.0, 0.0]}])
    plant.setup(0.0)
    start = plant.get_outputs()["body_position"].copy()
    for _ in range(round(t / DT)):
        plant.set_inputs({"q_target": plant.q0})
        plant.do_step(plant.time, DT)
    moved = plant.get_outputs()["body_position"] - start
    assert moved[0] == pytest.approx(force * duration * (t - duration / 2) / _mass(), rel=0.02)
    assert abs(moved[1]) < 1e-9
    assert moved[2] == pytest.approx(-0.5 * G * t**2, rel=0.02)
    assert not plant.toe_force_world().any() and not plant.body_contact()  # never touched anything
    plant.terminate()


@pytest.mark.parametrize("native", [False, True], ids=["python step", "c step"])
@pytest.mark.parametrize("engine", _engines("pushes", "native"))
def test_pushes_act_from_t0_not_in_the_settle_phase(engine, native):
    """The settle phase comes before the run's clock starts: a push timed at 0 s must not act in it (the
    MuJoCo plant's Python sub-steps applied it there before the step moved to the shared base; DART did not),
    in the Python step and in the C step alike."""
    outs = []
    for pushes in ([], [{"start_s": 0.0, "duration_s": 0.05, "force_N": [30.0, 0.0, 0.0]}]):
        plant = make_plant(engine, settle=0.2, disturbances=pushes, native=native)
        plant.setup(0.0)
        outs.append(np.concatenate([v.ravel() for v in plant.get_outputs().values()]))
        plant.terminate()
    np.testing.assert_array_equal(outs[1], outs[0])


@pytest.mark.parametrize("engine", _engines("amputation"))
def test_an_amputated_leg_touches_nothing_and_the_others_carry_the_weight(engine):
    """Fukuhara 2022, Sec. 3.2: an amputated leg keeps its mass but touches nothing. Standing on the other
    five: the amputated leg's toe force is exactly zero, none of its links is in contact, the five carry the
    robot's weight (2 %) and the body stays level within 2 degrees."""
    plant = make_plant(engine, settle=0.5, amputated=[1])
    plant.setup(0.0)
    for _ in range(300):
        plant.set_inputs({"q_target": plant.q0})
        plant.do_step(plant.time, DT)
        assert not plant.link_contacts()[1]
    fz = plant.toe_force_world()[:, 2]
    assert not plant.toe_force_world()[1].any()
    assert fz.sum() == pytest.approx(_mass() * G, rel=0.02)
    assert np.all(np.delete(fz, 1) > 0.1 * _mass() * G / 6), fz
    assert np.abs(plant.get_outputs()["body_rpy"][:2]).max() < np.radians(2)
    assert not plant.fell()
    plant.terminate()


def test_an_engine_missing_a_hook_cannot_be_built():
    """The contract is written as abstract methods of HexapodPlant: an engine's plant that leaves one out is
    refused when it is constructed, naming the hook (not at its first step, half-way through a run)."""
    from cpgsim.robots.plant_base import HexapodPlant

    hooks = {"_apply_servo", "_world_step", "_robot_contacts", "_contact_force", "_read_state", "_body_rotation",
             "_state_finite", "is_set_up"}
    assert HexapodPlant.__abstractmethods__ == hooks
    for engine in ENGINES.values():
        if engine.available():
            assert not engine.plant_class().__abstractmethods__
    incomplete = type("Incomplete", (HexapodPlant,), {h: None for h in hooks - {"_world_step"}})
    with pytest.raises(TypeError, match="_world_step"):
        incomplete("robot", YU_SIM, None, None, None, True, 0.0, None, ())


def test_a_third_engine_is_a_class_and_a_registry_line():
    """The stand-in engine (tests/point_feet_engine.py) declares no capability: it passes the contract tests
    every engine must (ports, parameters, a standing robot's weight: above), and every run that needs a
    capability is refused naming it, before anything is built."""
    assert point_feet_engine.ENGINE.capabilities == frozenset()
    plant = make_plant("point-feet")
    assert not isinstance(plant, ResumableBlock) and not isinstance(plant, FusedLoopBlock)
    with pytest.raises(ParameterError, match="a run with disturbances needs the pushes capability, which engine "
                                             "'point-feet' does not have"):
        make_plant("point-feet", disturbances=[{"start_s": 0.0, "duration_s": 0.1, "force_N": [1.0, 0.0, 0.0]}])
    with pytest.raises(ParameterError, match="an amputated robot needs the amputation capability, which engine "
                                             "'point-feet' does not have"):
        make_plant("point-feet", amputated=[1])
