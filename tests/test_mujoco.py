"""The MuJoCo plant: its model is the DART model (masses, inertias, kinematics, terrain), its ports are the
DART plant's, and scenarios switch engines with ``robot.engine`` (what every engine must do alike -- stand,
step in C as in Python, snapshot -- is tests/test_plant_contract.py)."""

from __future__ import annotations

import numpy as np
import pytest

mujoco = pytest.importorskip("mujoco", reason="the mujoco package is not installed (pip install 'cpgsim[mujoco]')")

from cpgsim.components.geometry import LEG_NAMES, YU_PROTOTYPE, YU_SIM  # noqa: E402
from cpgsim.robots import terrain as tr  # noqa: E402
from cpgsim.robots.dart.model import build_hexapod  # noqa: E402
from cpgsim.robots.dart.plant import DartHexapod  # noqa: E402
from cpgsim.robots.mujoco.mjcf import mjcf  # noqa: E402
from cpgsim.robots.mujoco.plant import MujocoHexapod  # noqa: E402
from cpgsim.robots.registry import make_plant  # noqa: E402


def _mj_inertia(model, body_id: int) -> np.ndarray:
    """Full inertia matrix (body frame, about the COM) from MuJoCo's principal moments and frame."""
    R = np.zeros(9)
    mujoco.mju_quat2Mat(R, model.body_iquat[body_id])
    R = R.reshape(3, 3)
    return R @ np.diag(model.body_inertia[body_id]) @ R.T


@pytest.mark.parametrize("geometry", [YU_SIM, YU_PROTOTYPE], ids=["yu-sim", "yu-prototype"])
def test_mjcf_mass_properties_equal_dart(geometry):
    dart_model = build_hexapod(geometry)
    model = mujoco.MjModel.from_xml_string(mjcf(geometry, tr.flat()))
    names = ["body"] + [f"{leg}_{link}" for leg in LEG_NAMES for link in ("coxa", "femur", "tibia")]
    assert model.nbody == 1 + len(names)
    skel = dart_model.skeleton
    for name in names:
        bn = skel.getBodyNode(name)
        b = model.body(name).id
        assert model.body_mass[b] == pytest.approx(bn.getMass(), rel=1e-12), name
        np.testing.assert_allclose(model.body_ipos[b], bn.getLocalCOM(), atol=1e-12, err_msg=name)
        np.testing.assert_allclose(_mj_inertia(model, b), bn.getInertia().getMoment(), rtol=1e-6, atol=1e-14,
                                   err_msg=name)
    assert model.body_mass[1:].sum() == pytest.approx(geometry.mass, rel=1e-12)


def test_mjcf_joints_match_dart_kinematics():
    """Same joint order, no limits (as in DART), and the same foot and link positions for random angles."""
    geometry = YU_SIM
    dart_model = build_hexapod(geometry)
    model = mujoco.MjModel.from_xml_string(mjcf(geometry, tr.flat()))
    data = mujoco.MjData(model)
    hinge_names = [model.joint(j).name for j in range(1, model.njnt)]
    assert hinge_names == [j.getName() for j in dart_model.joints]
    assert not model.jnt_limited.any()
    assert not any(j.areLimitsEnforced() for j in dart_model.joints)
    rng = np.random.default_rng(3)
    for _ in range(3):
        q = rng.uniform(-1.0, 1.0, 18)
        dart_model.set_joint_angles(q)
        dart_model.set_body_pose([0.1, -0.2, 0.3])
        data.qpos[:3] = (0.1, -0.2, 0.3)
        data.qpos[3:7] = (1, 0, 0, 0)
        data.qpos[7:] = q
        mujoco.mj_kinematics(model, data)
        for i, leg in enumerate(LEG_NAMES):
            np.testing.assert_allclose(data.geom_xpos[model.geom(f"{leg}_foot").id], dart_model.foot_positions()[i],
                                       atol=1e-12)
            for k, link in enumerate(("coxa", "femur", "tibia")):
                T = dart_model.link_bodies[i][k].getWorldTransform()
                np.testing.assert_allclose(data.xpos[model.body(f"{leg}_{link}").id], T.translation(), atol=1e-12)
                np.testing.assert_allclose(data.xmat[model.body(f"{leg}_{link}").id].reshape(3, 3), T.rotation(),
                                           atol=1e-12)


def test_mjcf_terrain_boxes_and_friction():
    terrain = tr.step(height=0.04, position_y=0.355, side="right", friction=0.6)
    model = mujoco.MjModel.from_xml_string(mjcf(YU_SIM, terrain, friction=0.9))
    for k, b in enumerate(terrain.boxes):
        g = model.geom(f"ground_{k}")
        assert g.pos[2] + g.size[2] == pytest.approx(b.top)
        assert g.pos[0] - g.size[0] == pytest.approx(b.x0) and g.pos[1] + g.size[1] == pytest.approx(b.y1)
        assert g.friction[0] == pytest.approx(0.6)  # DART's rule: the smaller of the two coefficients
    assert model.geom("L1_foot").friction[0] == pytest.approx(0.9)
    assert model.geom("L1_foot").size[0] == pytest.approx(YU_SIM.leg.foot_radius)


def test_ports_and_parameters_equal_dart():
    m, d = MujocoHexapod(), DartHexapod()
    assert list(m.inputs) == list(d.inputs) and list(m.outputs) == list(d.outputs)
    for a, b in [(m.inputs, d.inputs), (m.outputs, d.outputs), (m.parameters, d.parameters)]:
        for key in b:
            assert repr(a[key]) == repr(b[key]), key



def test_servo_law_is_darts():
    """The actuator force is DART's ``-kp (q + h qd - q_target) - kd qd``."""
    plant = MujocoHexapod(kp=50.0, kd=0.7)
    plant.setup(0.0)
    data, model = plant.data, plant.model
    target = plant.q0 + 0.1
    plant.set_inputs({"q_target": target})
    plant._update_servo(1e-3)
    data.qvel[6:] = np.linspace(-1, 1, 18)
    mujoco.mj_forward(model, data)
    q, qd, h = data.qpos[7:], data.qvel[6:], plant.time_step
    np.testing.assert_allclose(data.actuator_force, -50.0 * (q + h * qd - target) - 0.7 * qd, rtol=1e-12)


def test_make_plant_and_scenario_engine():
    from cpgsim.experiments.runner import build_scenario
    from cpgsim.experiments.scenario import ScenarioError

    assert isinstance(make_plant("mujoco", "robot"), MujocoHexapod)
    assert isinstance(make_plant("dart", "robot"), DartHexapod)
    setup = build_scenario("step", {"robot.engine": "mujoco"})
    assert isinstance(setup.graph.blocks["robot"], MujocoHexapod)
    assert setup.info["engine"] == "mujoco"
    assert isinstance(build_scenario("step").graph.blocks["robot"], DartHexapod)  # DART stays the default
    with pytest.raises(ScenarioError, match="robot.engine must be one of dart, mujoco"):
        build_scenario("step", {"robot.engine": "bullet"})


def test_scenario_contact_model_reaches_the_compiled_mujoco_model():
    """``[robot.mujoco]`` values end up in MuJoCo's compiled model (read back from ``mjModel``, not from the
    MJCF text cpgsim writes), on every robot and terrain geom; the run's summary says which model ran."""
    from cpgsim.experiments.runner import build_scenario

    sets = {"robot.engine": "mujoco", "robot.mujoco.noslip_iterations": 7, "robot.mujoco.cone": "pyramidal",
            "robot.mujoco.impratio": 4.0, "robot.mujoco.solref": [0.004, 0.9],
            "robot.mujoco.solimp": [0.8, 0.95, 0.002], "robot.mujoco.condim": 1}
    setup = build_scenario("step", sets)
    plant = setup.graph.blocks["robot"]
    plant.setup(0.0)
    m = plant.model
    assert m.opt.noslip_iterations == 7 and m.opt.impratio == 4.0
    assert m.opt.cone == mujoco.mjtCone.mjCONE_PYRAMIDAL
    assert m.ngeom > 19  # every robot shape and the terrain's boxes
    np.testing.assert_array_equal(m.geom_solref, np.tile([0.004, 0.9], (m.ngeom, 1)))
    np.testing.assert_array_equal(m.geom_solimp[:, :3], np.tile([0.8, 0.95, 0.002], (m.ngeom, 1)))
    assert np.all(m.geom_condim == 1)
    assert setup.info["mujoco_contact"]["noslip_iterations"] == 7
    assert setup.info["mujoco_contact"]["solref"] == [0.004, 0.9]
    default = build_scenario("step", {"robot.engine": "mujoco"}).graph.blocks["robot"]
    default.setup(0.0)
    # the default: Coulomb's cone with hard friction (docs/engines.md), noslip off
    assert default.model.opt.noslip_iterations == 0 and default.model.opt.cone == mujoco.mjtCone.mjCONE_ELLIPTIC
    assert default.model.opt.impratio == 100.0
    np.testing.assert_array_equal(default.model.geom_solref[0], [0.005, 1.0])


@pytest.mark.parametrize("key, value, message", [
    ("solref", [0.005], r"robot\.mujoco\.solref must be 2 numbers"),
    ("solref", [-2000.0, -50.0], r"robot\.mujoco\.solref = .* must both be > 0"),
    ("solimp", [0.9, 1.5, 0.001], r"robot\.mujoco\.solimp .* 0 < d0, dwidth < 1"),
    ("solimp", [0.9, "x", 0.001], r"robot\.mujoco\.solimp\[1\] must be a finite number"),
    ("cone", "ellipse", r"robot\.mujoco\.cone must be one of pyramidal, elliptic"),
    ("condim", 2, r"robot\.mujoco\.condim must be one of 1, 3, 4, 6"),
    ("impratio", 0.0, r"robot\.mujoco\.impratio = 0.0 is out of range"),
    ("noslip_iterations", -1, r"robot\.mujoco\.noslip_iterations = -1 is out of range"),
    ("noslip_iterations", 2.5, r"robot\.mujoco\.noslip_iterations must be an integer"),
    ("impratoi", 2.0, r"unknown key 'robot\.mujoco\.impratoi'.*did you mean 'impratio'"),
])
def test_scenario_contact_model_rejects_bad_values(key, value, message):
    from cpgsim.experiments.runner import build_scenario
    from cpgsim.experiments.scenario import ScenarioError

    with pytest.raises(ScenarioError, match=message):
        build_scenario("step", {"robot.engine": "mujoco", f"robot.mujoco.{key}": value})


def test_scenario_contact_model_on_dart_is_an_error_and_its_fields_are_contactmodels():
    """A ``[robot.mujoco]`` table on a DART run would do nothing: an error naming both keys. The schema's
    keys are :class:`ContactModel`'s fields (one list of settable fields)."""
    from cpgsim.experiments.runner import build_scenario
    from cpgsim.experiments.scenario import MUJOCO_SCHEMA, ScenarioError
    from cpgsim.robots.mujoco.mjcf import ContactModel

    with pytest.raises(ScenarioError, match=r"robot\.mujoco sets MuJoCo's contact model \(impratio\).*"
                                            r"robot\.engine = 'dart'"):
        build_scenario("step", {"robot.mujoco.impratio": 10.0})
    with pytest.raises(ScenarioError, match="robot.mujoco sets"):
        build_scenario("fukuhara-gap", {"robot.mujoco.cone": "elliptic"})
    assert tuple(MUJOCO_SCHEMA) == ContactModel.fields()
    with pytest.raises(Exception, match="contact .* applies to engine 'mujoco'"):
        make_plant("dart", "robot", contact=ContactModel())


def test_report_names_the_engine_and_contact_model():
    """report.html's facts table says which engine ran and MuJoCo's contact settings."""
    from cpgsim.experiments.report import _summary_html

    page = _summary_html({"scenario": "step", "engine": "mujoco", "reflexes": [],
                          "mujoco_contact": {"solref": [0.002, 1.0], "noslip_iterations": 20}})
    assert "<th>engine</th><td>mujoco</td>" in page
    assert "<th>mujoco_contact</th><td>solref [0.002, 1.0], noslip_iterations 20</td>" in page


def test_native_step_equals_python_step():
    """The C macro step (mj_step + contact sums in C) gives bit-identical outputs to the Python sub-steps."""

    outs = {}
    for native in (True, False):
        plant = MujocoHexapod(settle=0.1, native=native, time_step=5e-4,
                              terrain=tr.step(height=0.04, position_y=0.2, side="right"))
        plant.setup(0.0)
        if native and plant.native_step is None:
            pytest.skip("no C compiler or no libmujoco for the native step")
        assert (plant.native_step is not None) == native
        for k in range(150):
            q = plant.q0.copy()
            q[9::3] += 0.3 * np.sin(0.02 * k)  # R-legs swing: contacts come and go
            plant.set_inputs({"q_target": q})
            plant.do_step(k * 1e-3, 1e-3)  # two MuJoCo steps per macro step: averaging too
        outs[native] = plant.get_outputs()
    for key, value in outs[True].items():
        np.testing.assert_array_equal(value, outs[False][key], err_msg=key)
    assert np.abs(outs[True]["toe_force"]).sum() > 1.0



@pytest.mark.slow
def test_mjcf_terrain_of_every_feature_has_the_terrains_heights():
    """Steps, ditches, gaps, stairs and blocks: a ray cast down in MuJoCo meets the ground at height_at."""
    feats = {
        "b": {"type": "ditch", "depth": 0.04, "width": 0.1, "position_y": 0.4, "side": "left"},
        "c": {"type": "gap", "width": 0.08, "position_y": 0.7, "side": "both"},
        "e": {"type": "blocks", "position_y": 1.0, "length": 0.5, "half_width": 0.3, "size": 0.05,
              "height_min": 0.0, "height_max": 0.03, "seed": 4, "side": "both"},
        "d": {"type": "stairs", "rise": 0.02, "run": 0.1, "count": 3, "position_y": 1.8, "side": "left"},
        "a": {"type": "step", "height": 0.03, "position_y": 1.8, "side": "right"},
    }
    terrain = tr.compose(feats, 1.0)
    model = mujoco.MjModel.from_xml_string(mjcf(YU_SIM, terrain))
    data = mujoco.MjData(model)
    data.qpos[2] = 10.0  # the robot far above the rays
    mujoco.mj_forward(model, data)
    rng = np.random.default_rng(0)
    geomid = np.zeros(1, dtype=np.int32)
    hits = holes = 0
    for x, y in zip(rng.uniform(-0.5, 0.5, 400), rng.uniform(0.0, 2.6, 400), strict=True):
        d = mujoco.mj_ray(model, data, np.array([x, y, 1.0]), np.array([0.0, 0.0, -1.0]), None, 1, 1, geomid)
        expected = terrain.height_at(x, y)
        if np.isfinite(expected) and expected > -0.5:
            assert d >= 0 and 1.0 - d == pytest.approx(expected, abs=1e-9), (x, y)
            hits += 1
        else:  # a bottomless gap: nothing (or only the far bottom of the world) below
            assert d < 0 or 1.0 - d < -0.5, (x, y)
            holes += 1
    assert hits > 300 and holes > 0


@pytest.mark.slow  # a 6 s Fukuhara run
def test_fukuhara_amputation_runs_on_mujoco_with_the_cut_legs_touching_nothing():
    """Fukuhara 2022, Sec. 3.2: the middle legs (case 1: L2, R2) are taken out; on MuJoCo their geoms do not
    collide, so their toe force is exactly zero all run, while the four others carry the robot's weight
    (35.5 N) between them."""
    from cpgsim.experiments.runner import build_scenario
    from cpgsim.harness.simulate import Simulator

    setup = build_scenario("fukuhara-amputation", {"robot.engine": "mujoco", "controller.case": 1})
    res = Simulator(setup.graph, dt=1e-3, record=["robot.toe_force"]).run(6.0)
    force = res["robot.toe_force"].reshape(len(res.time), 6, 3)
    assert np.all(force[:, [1, 4]] == 0.0)  # L2, R2
    fz = force[:, [0, 2, 3, 5], 2].sum(axis=1)
    assert np.median(fz[len(fz) // 2:]) == pytest.approx(setup.geometry.mass * 9.81, rel=0.1)


@pytest.mark.slow  # two closed-loop 35 s runs
def test_step_in_mujoco_elevates_r1_r2_r3_in_order_and_succeeds(tmp_path):
    """Issue 28's must-show, Yu 2019 Sec. 6.1.1 in MuJoCo: on the 40 mm step (at 0.41 m, where every right
    foot reaches the riser below its top) the elevator reflex fires on legs 4, 5, 6 (R1, R2, R3) in that
    order and on no other leg, each triggered by a horizontal toe force above Fcy = 10 N, and the run
    succeeds. With MuJoCo's own soft friction (pyramidal cone, impratio 1) R3 arrives at the riser just
    above its top and slides onto it where a Coulomb foot is arrested: no R3 (docs/engines.md) -- the
    reason the MuJoCo default is Coulomb's cone."""
    from cpgsim.experiments.runner import run_scenario
    from cpgsim.experiments.setup import ENGINE_CONFIGS

    summary = run_scenario("step", tmp_path / "run", sets={"robot.engine": "mujoco"}, progress=False,
                           plots=False)
    elevators = [e for e in summary["reflexes"] if e["kind"] == "elevator"]
    assert [e["leg"] for e in elevators] == ["R1", "R2", "R3"], summary["reflexes"]
    assert all(e["force_N"] > 10.0 for e in elevators)
    assert np.all(np.diff([e["t"] for e in elevators]) > 2.0)  # gait cycles apart (Yu: 3.7 s, 4.2 s)
    assert summary["success"] and summary["complete"] and summary["engine"] == "mujoco"
    soft = run_scenario("step", tmp_path / "soft", sets=ENGINE_CONFIGS["mujoco-soft"], progress=False, plots=False)
    assert [e["leg"] for e in soft["reflexes"] if e["kind"] == "elevator"] == ["R1", "R2"]
