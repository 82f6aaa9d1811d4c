"""Where a gait's speed comes from (experiments/gait_speed.py): checked on a hand-built walk, then on Fukuhara's
tripod and tetrapod in both engines."""

from __future__ import annotations

import numpy as np
import pytest

from cpgsim.experiments.gait_speed import stance_kinematics

DT = 1e-3


def test_a_tripod_that_does_not_slip():
    """A body at 0.1 m/s on legs of period 2 s and duty 0.5 whose feet stay put in stance: each stance lasts 1 s
    and sweeps 0.1 m back relative to the body, slip 0, speed = sweep / stance."""
    t = np.arange(0.0, 10.0, DT)
    v, period, duty = 0.1, 2.0, 0.5
    body = np.column_stack([np.zeros_like(t), v * t, np.full_like(t, 0.12)])
    stance = np.zeros((len(t), 6), dtype=bool)
    feet = np.zeros((len(t), 6, 3))
    for i in range(6):
        u = (t / period - (0.5 if i in (1, 3, 5) else 0.0)) % 1.0
        stance[:, i] = u < duty
        cycle = np.floor(t / period - (0.5 if i in (1, 3, 5) else 0.0))
        start = (cycle + (0.5 if i in (1, 3, 5) else 0.0)) * period
        planted = v * start + 0.05  # the foot lands 5 cm ahead of the body and stays there
        feet[:, i, 1] = np.where(stance[:, i], planted, v * t + 0.05)
    k = stance_kinematics(t, stance, body, feet.reshape(len(t), 18), t_start=1.0)
    assert k.speed == pytest.approx(v, rel=1e-9)
    assert k.period == pytest.approx(period, abs=2 * DT) and k.duty == pytest.approx(duty, abs=0.01)
    assert k.stance == pytest.approx(period * duty, abs=2 * DT)
    assert k.sweep == pytest.approx(v * period * duty, abs=v * 2 * DT)
    assert k.slip == pytest.approx(0.0, abs=1e-12)
    assert k.speed == pytest.approx(k.sweep / k.stance, rel=0.01)


@pytest.mark.slow
@pytest.mark.parametrize("engine", ["dart", "mujoco"])
def test_fukuhara_speed_follows_the_stance_frequency(engine):
    """Fukuhara 2022, Sec. 3.1: tripod (omega_st = pi/3) and tetrapod (pi/6). Measured (docs/fidelity.md): the
    stance sweep is the same in both (about 0.11 m, within 5 %), the feet slip under 3 mm, so the speed ratio is
    the stance frequency's, 1/2, not the paper's 8.8 / 10.7 = 0.82."""
    from cpgsim.experiments.runner import build_scenario
    from cpgsim.harness.simulate import Simulator

    if engine == "mujoco":
        pytest.importorskip("mujoco")
    out = {}
    for setting in (1, 2):
        setup = build_scenario("fukuhara-gaits", {"robot.engine": engine, "setting": setting})
        res = Simulator(setup.graph, dt=1e-3, record=[*(setup.record or []), f"{setup.robot}.*"]).prepare().run(
            setup.t_end)
        out[setting] = stance_kinematics(res.time, setup.stance(res), res[f"{setup.robot}.body_position"],
                                         res[f"{setup.robot}.foot_position"], t_start=10.0)
    tripod, tetrapod = out[1], out[2]
    assert tetrapod.sweep == pytest.approx(tripod.sweep, rel=0.05)
    assert max(tripod.slip, tetrapod.slip) < 3e-3
    assert tetrapod.speed / tripod.speed == pytest.approx(0.5, abs=0.03)
    for k in (tripod, tetrapod):
        assert k.speed == pytest.approx(k.sweep / k.stance, rel=0.05)
