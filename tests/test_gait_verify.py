"""Tests of the closed-loop gait verification (``cpgsim verify gait``): exact save/restore of a
co-simulation, the return-map numerics, a hybrid toy with an analytic multiplier run through the same
stride-map code, and the hexapod's gait."""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from hybrid_toys import BallCoordinates, KickedBall  # noqa: E402

from cpgsim.cli.main import main  # noqa: E402
from cpgsim.components.graph import Graph  # noqa: E402
from cpgsim.harness.simulate import Simulator  # noqa: E402
from cpgsim.verify import return_map as rm  # noqa: E402
from cpgsim.verify.gait import GaitOptions, analyze  # noqa: E402
from cpgsim.verify.stride import Section, SectionError, StrideMap  # noqa: E402

G = 9.81


# -- the return-map numerics on maps whose answers are known ---------------------------------------------

def _linear(a: np.ndarray, b: np.ndarray):
    def P(r):
        return a @ r + b, {"signature": None}
    return P


def test_jacobian_newton_and_decay_of_a_linear_map():
    rho, th = 0.7, 0.4  # a rotation-scaling: multipliers rho e^{+-i th}, every distance shrinks by rho
    a = rho * np.array([[math.cos(th), -math.sin(th)], [math.sin(th), math.cos(th)]])
    b = np.array([0.3, -0.2])
    P = _linear(a, b)
    scale = np.array([2.0, 0.5])
    r0 = np.array([1.0, 1.0])
    img, info = P(r0)
    fp = rm.FixedPoint(r0, img, info, rm.scaled_residual(img, r0, scale))
    est = rm.jacobian(P, fp, scale, 1e-3)
    assert np.allclose(sorted(np.abs(est.multipliers)), [rho, rho], atol=1e-9)
    assert abs(abs(np.angle(est.multipliers[0])) - th) < 1e-9
    fixed = rm.newton(P, fp, est.matrix, scale, steps=2)
    exact = np.linalg.solve(np.eye(2) - a, b)
    assert np.allclose(fixed.r, exact, atol=1e-12) and fixed.newton_steps >= 1
    # distances shrink by exactly rho per stride in the coordinates where the map is a rotation-scaling
    pert = rm.perturbation_decay(P, fixed, rm.leading_real_direction(est), np.ones(2), 1e-2, 5)
    assert pert["measured"] == pytest.approx(rho, rel=1e-9) and pert["strides_used"] == 5
    assert pert["measured_from_start"] == pytest.approx(rho, rel=1e-9)


def test_compare_multipliers_pairs_by_nearest():
    a = np.array([0.9, 0.5 + 0.1j, 0.5 - 0.1j])
    assert rm.compare_multipliers(a, a[::-1]) == 0.0
    assert rm.compare_multipliers(a, a + np.array([0.09, 0, 0])) == pytest.approx(0.09 / 0.99)


def test_a_kink_is_reported_by_the_signature():
    def P(r):  # slope 0.5 left of 0, 0.9 right of it: the "contact" is the sign of r
        x = float(r[0])
        return np.array([0.5 * x if x < 0 else 0.9 * x]), {"signature": x < 0}

    img, info = P(np.array([1e-9]))
    fp = rm.FixedPoint(np.array([1e-9]), img, info, 0.0)
    est = rm.jacobian(P, fp, np.array([1.0]), 1e-3, central=True)
    assert est.signature_changed == [0]
    assert est.multipliers[0].real == pytest.approx(0.7, abs=1e-6)  # the secant across the kink


# -- the hybrid toy: a kicked bouncing ball, through the co-simulation master and the stride map ----------

def ball_map(e: float, c: float, t_max: float = 10.0) -> tuple[StrideMap, Simulator]:
    g = Graph("ball_loop", "kicked bouncing ball")
    g.add(KickedBall("ball", h0=0.4, e=e, c=c, g=G))
    sim = Simulator(g, dt=1e-3)
    sim.run(0.3)
    return StrideMap(sim, Section("ball.v", 0.0, -1, min_time=0.05), t_max=t_max), sim


@pytest.mark.slow
@pytest.mark.parametrize("e, c", [(0.6, 2.0), (0.3, 3.0)])
def test_bouncing_ball_apex_map_multiplier_is_the_restitution(e, c):
    smap, sim = ball_map(e, c)
    start = smap(sim.snapshot()).state
    res = analyze(smap, BallCoordinates(), start,
                  GaitOptions(h=(1e-3, 1e-4), central=True, tol=1e-9, transient=80, newton=2, perturb_eps=1e-3,
                              perturb_strides=4))
    v_star = c / (1 - e)
    assert abs(res.multipliers[0] - e) < 1e-6  # dh'/dh = e v+/v- = e at the fixed point
    assert res.fd_agreement < 1e-6
    assert res.fixed_point.r[0] == pytest.approx(v_star**2 / (2 * G), rel=1e-9)
    assert res.period == pytest.approx(2 * v_star / G, rel=1e-9)
    assert res.stable
    assert res.perturbation["measured"] == pytest.approx(e, rel=2e-3)
    assert res.nonsmooth_columns(0.05) == []
    # the neutral direction: the ball drifted sideways, and no coordinate measures it
    assert start.blocks["ball"].x != res.state.blocks["ball"].x and "ball.x" not in BallCoordinates.names


def test_ball_save_restore_is_bit_identical():
    smap, sim = ball_map(0.6, 2.0)
    snap = sim.snapshot()
    a = sim.run(snap.t + 0.8, resume=snap)
    b = sim.run(snap.t + 0.8, resume=snap)
    straight = sim.run(snap.t + 0.8, resume=snap)
    assert np.array_equal(a.data, b.data) and np.array_equal(a.data, straight.data)


@pytest.mark.slow
def test_a_block_that_cannot_save_its_state_is_named():
    from cpgsim.components.core import CoSimBlock
    from cpgsim.harness.errors import SimulationError

    class Opaque(CoSimBlock):
        def declare(self) -> None:
            self.add_output("y", 1, "1")

        def get_outputs(self):
            return {"y": np.zeros(1)}

        def set_inputs(self, values) -> None:
            pass

        def do_step(self, t: float, dt: float) -> None:
            pass

    g = Graph("opaque_loop", "a block without snapshot")
    g.add(Opaque("box"))
    sim = Simulator(g, dt=1e-3)
    sim.run(0.01)
    with pytest.raises(SimulationError, match="block 'box' \\(Opaque\\) cannot save its state"):
        sim.snapshot()


def test_a_section_never_crossed_is_a_one_line_error():
    smap, sim = ball_map(0.6, 2.0, t_max=0.5)
    smap.section = Section("ball.x", -1.0, -1, min_time=0.05)  # x only grows: never crosses -1 downwards
    with pytest.raises(SectionError, match=r"ball\.x crossing -1 downwards.*not crossed within 0\.5 s"):
        smap(sim.snapshot())


# -- the hexapod closed loop ---------------------------------------------------------------------------

@pytest.fixture(scope="module")
def flat_loop():
    from cpgsim.experiments.runner import build_scenario

    setup = build_scenario("flat")
    sim = Simulator(setup.graph, dt=1e-3, record=setup.record).prepare()
    return setup, sim


@pytest.mark.slow
def test_hexapod_save_run_restore_run_is_bit_identical(flat_loop):
    setup, sim = flat_loop
    straight = sim.run(2.5)
    sim.run(2.0)  # walking: feet in contact, legs swinging, FSM switching
    snap = sim.snapshot()
    first = sim.run(2.5, resume=snap)
    again = sim.run(2.5, resume=snap)
    k = 2000
    assert first.time[0] == 2.0 and len(first.time) == 501
    assert np.array_equal(first.data, again.data)
    assert np.array_equal(first.data, straight.data[k:])
    # the run really moved: contacts changed and the body advanced over the resumed half second
    assert np.ptp(first["robot.body_position"][:, 1]) > 1e-3
    # the plant's own save/restore in a running world gives the same
    plant = sim.model.flat.cosim_blocks()["robot"]
    assert plant.last_snapshot.t == 2.5


def test_hexapod_coordinates_drop_heading_and_position(flat_loop):
    from cpgsim.experiments.gait_coords import HexapodCoordinates, body_pose, with_body_pose

    setup, sim = flat_loop
    sim.run(1.0)
    snap = sim.snapshot()
    coords = HexapodCoordinates(sim.model, "robot", "controller.L1.network.z1.x")
    r = coords.reduce(snap)
    assert np.allclose(coords.reduce(coords.embed(snap, r)), r, atol=1e-14)
    plant = snap.blocks["robot"]
    trans, rpy = body_pose(plant.positions)
    moved = with_body_pose(plant.positions, trans + [0.3, -0.2, 0.0], rpy + [0.0, 0.0, 0.7])  # x, y, yaw
    turned = snap.replace(blocks={"robot": plant.replace(positions=moved)})
    assert np.allclose(coords.reduce(turned), r, atol=1e-12)
    tilted = with_body_pose(plant.positions, trans, rpy + [0.01, 0.0, 0.0])  # roll is not neutral
    assert not np.allclose(coords.reduce(snap.replace(blocks={"robot": plant.replace(positions=tilted)})), r)
    assert {"body yaw", "body forward position (world y)"} <= set(coords.removed)
    assert "controller.L1.network.z1.x" not in coords.names


def test_the_body_pose_reads_darts_free_joint_as_dart_does():
    """The free joint's (rotation vector, translation) against dartpy's own FreeJoint conversions, both ways,
    on random poses (rotations up to 3.4 rad, near the rotation vector's branch at pi)."""
    dart = pytest.importorskip("dartpy")
    from cpgsim.experiments.gait_coords import body_pose, with_body_pose
    from cpgsim.robots.description import rotation_from_rpy

    rng = np.random.default_rng(7)
    for _ in range(20):
        q = np.r_[rng.normal(size=3) * rng.uniform(0, 3.4) / np.sqrt(3), rng.uniform(-1, 1, 3), rng.normal(size=4)]
        tf = dart.dynamics.FreeJoint.convertToTransform(q[:6])
        trans, rpy = body_pose(q)
        np.testing.assert_allclose(trans, np.array(tf.translation()), rtol=0, atol=1e-15)
        np.testing.assert_allclose(rotation_from_rpy(*rpy), np.array(tf.rotation()), rtol=0, atol=1e-12)
        back = with_body_pose(q, trans, rpy)
        expected = dart.dynamics.FreeJoint.convertToPositions(tf)
        np.testing.assert_allclose(back[:6], expected, rtol=0, atol=1e-9)
        assert np.array_equal(back[6:], q[6:])  # the joint angles are left alone


def test_verify_gait_bad_input_is_one_line(tmp_path, capsys):
    assert main(["verify", "gait", "-o", str(tmp_path / "a")]) == 2
    assert "needs a SCENARIO" in capsys.readouterr().err
    assert main(["verify", "gait", "no-such-scenario", "-o", str(tmp_path / "b")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "unknown scenario 'no-such-scenario'" in err[0]
    assert main(["verify", "gait", "step", "-o", str(tmp_path / "c")]) == 2
    assert "terrain features" in capsys.readouterr().err
    assert main(["verify", "gait", "flat", "--fd-steps", "0.01", "-o", str(tmp_path / "d")]) == 2
    assert not (tmp_path / "d").exists()
    pytest.importorskip("mujoco")
    assert main(["verify", "gait", "flat", "--set", "robot.engine=mujoco", "-o", str(tmp_path / "e")]) == 2
    assert "written for DART's free joint, not engine 'mujoco'" in capsys.readouterr().err


@pytest.mark.slow
def test_cli_verify_gait_flat(tmp_path, capsys):
    out = tmp_path / "gait"
    assert main(["verify", "gait", "flat", "-o", str(out)]) == 0
    doc = json.loads((out / "gait.json").read_text())
    for key in ("period_s", "multipliers", "fd_agreement", "perturbation", "stable", "section", "removed_directions"):
        assert key in doc
    assert (out / "gait.png").stat().st_size > 10_000
    # Yu's FSM: the tripod cycle is T_g = 5 s (Y16); the closed loop keeps it within a few ms
    assert doc["period_s"] == pytest.approx(5.0, abs=0.02)
    mods = [abs(complex(*m)) for m in doc["multipliers"]]
    assert doc["stable"] and doc["status"] == "stable" and max(mods) < 1
    # the slowest mode is the CPG network's own follower mode (shooting + CVODES, docs/verification.md:
    # 0.778805), once per leg: the mechanics and the FSM-corrected leg phases decay faster
    assert max(mods) == pytest.approx(0.778805, abs=3e-3)
    assert sum(abs(m - 0.778805) < 3e-3 for m in mods) == 6
    assert len(doc["multipliers"]) == len(doc["coordinates"]) == 44
    assert doc["fd_agreement"] < 0.2
    p = doc["perturbation"]
    assert p["measured"] == pytest.approx(p["predicted"], abs=0.15)
    assert "body yaw" in doc["removed_directions"]
    text = capsys.readouterr().out
    assert "STABLE" in text and "perturbation" in text


@pytest.mark.slow
def test_gait_study_over_the_fsm_period():
    """Yu's tripod FSM scales the whole network's clock by T_net/T_g (Y16, swing and stance alike for
    gamma = 2): the gait period follows T_g and the multipliers per stride do not change."""
    from cpgsim.experiments.gait_study import study

    rows = study("flat", {}, "controller.fsm.T_g", [4.0, 6.0])
    assert [r["value"] for r in rows] == [4.0, 6.0]
    for r in rows:
        assert r["status"] == "stable"
        # the network's own period (CVODES shooting, docs/verification.md: 5.0019786 s at T_net = 5 s) scaled
        # by T_g / T_net, plus one 1 ms grid step of waiting at each of the cycle's two slot switches
        assert r["period_s"] == pytest.approx(5.0019786 * r["value"] / 5.0 + 0.002, abs=1e-5)
        assert r["max_abs_multiplier"] == pytest.approx(0.778805, abs=3e-3)
