"""The sensing-lag option of the Yu sensory neurons (docs/fidelity.md open item 2): a first-order
low-pass ``tau_f`` and a pure delay ``delay_f`` on the force that Y8 reads, both off by default; scripted
inputs on the block alone."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cpgsim.components.core import ParameterError
from cpgsim.components.yu.sensors import YuSensoryNeurons
from cpgsim.harness.simulate import simulate

DT = 0.001
N = 101


def run(fy_from: int = 20, fy: float = 20.0, fz: float = 5.0, **params) -> dict[str, np.ndarray]:
    tf = np.zeros((3, N))
    tf[2] = fz
    tf[1, fy_from:] = fy
    r = simulate(YuSensoryNeurons("s", **params), t_end=(N - 1) * DT, dt=DT, inputs={"toe_force": tf},
                 backend="casadi")
    return {k.split(".", 1)[-1]: np.asarray(r[k]) for k in r.columns}


def test_without_a_time_constant_the_force_passes_unchanged():
    r = run()
    assert np.allclose(r["force_f[1]"][20:], 20.0) and np.allclose(r["force_f[1]"][:20], 0.0)
    assert np.flatnonzero(r["raw_ob"] > 0.5)[0] == 20


@pytest.mark.parametrize("tau", [0.005, 0.01, 0.04])
def test_the_low_pass_follows_a_first_order_step_response_and_delays_the_obstacle_flag(tau):
    r = run(tau_f=tau)
    k = np.arange(20, N)
    expect = 20.0 * (1 - np.exp(-(k - 19) * DT / tau))
    assert np.allclose(r["force_f[1]"][20:], expect, rtol=1e-6, atol=1e-9)
    cross = np.flatnonzero(r["force_f[1]"] > 10.0)[0]  # first sample the filtered force exceeds Fcy = 10 N
    assert cross - 19 == pytest.approx(-tau * math.log(0.5) / DT, abs=1.0)
    base = run()
    lag = np.flatnonzero(base["lambda_ob"] > 0.5)[0] - 20  # the debounce alone
    assert np.flatnonzero(r["lambda_ob"] > 0.5)[0] == cross + lag


def test_the_low_pass_leaves_touchdown_and_support_on_the_raw_force():
    a, b = run(fz=3.0, fy=0.0), run(fz=3.0, fy=0.0, tau_f=0.04)
    for key in ("lambda_td", "support", "raw_td", "raw_sup"):
        assert np.array_equal(a[key], b[key])


def test_the_first_sample_starts_the_filter_on_the_force():
    r = run(fy_from=0, tau_f=0.04)
    assert r["force_f[1]"][0] == pytest.approx(20.0)


# -- the pure delay ``delay_f`` (a delay line of DELAY_SAMPLES samples, k = round(delay_f / dt)) ------


@pytest.mark.parametrize(("delay", "k"), [(0.001, 1), (0.005, 5), (0.0124, 12), (0.0126, 13), (0.05, 50)])
def test_the_delay_shifts_the_force_and_the_obstacle_flag_by_exactly_k_samples(delay, k):
    # a 20 N step in Fy at sample 20: Y8 (|Fy| > 10 N) reads it k = round(delay / 1 ms) samples later
    base, r = run(), run(delay_f=delay)
    expect = np.zeros(N)
    expect[20 + k:] = 20.0
    assert np.array_equal(r["force_f[1]"], expect)
    assert np.flatnonzero(r["raw_ob"] > 0.5)[0] == 20 + k
    assert np.flatnonzero(r["lambda_ob"] > 0.5)[0] == np.flatnonzero(base["lambda_ob"] > 0.5)[0] + k
    for key in ("lambda_td", "support", "raw_td", "raw_sup"):  # Y9 and support keep the raw force
        assert np.array_equal(base[key], r[key])


def test_delay_zero_is_the_old_behaviour_bit_for_bit():
    a, b = run(), run(delay_f=0.0)
    assert a.keys() == b.keys()
    for key in a:
        assert np.array_equal(a[key], b[key]), key


def test_before_the_first_sample_the_delayed_force_is_the_first_sample():
    r = run(fy_from=0, delay_f=0.01)
    assert np.array_equal(r["force_f[1]"], np.full(N, 20.0))


def test_the_low_pass_acts_on_the_delayed_force():
    # delay then low-pass: the first-order step response of the low-pass test, started k = 10 samples later
    tau = 0.01
    r = run(delay_f=0.01, tau_f=tau)
    assert np.array_equal(r["force_f[1]"][:30], np.zeros(30))
    k = np.arange(30, N)
    assert np.allclose(r["force_f[1]"][30:], 20.0 * (1 - np.exp(-(k - 29) * DT / tau)), rtol=1e-6, atol=1e-9)


def test_a_delay_beyond_the_line_is_refused():
    with pytest.raises(ParameterError, match="delay_f"):
        YuSensoryNeurons("s", delay_f=0.051)
    with pytest.raises(ParameterError, match="delay_f"):
        YuSensoryNeurons("s", delay_f=-0.001)


def test_setting_the_delay_on_a_controller_built_without_it_says_how_to_build_it():
    """The delay line is built only when asked for (docs/performance.md): a ``*.sensors.delay_f`` on a default
    controller matches no parameter, and the error names the option that builds it."""
    from cpgsim.components.yu.leg import hexapod_controller

    with pytest.raises(ParameterError, match=r"no parameter matching '\*\.sensors\.delay_f' \(L1\.sensors\.delay_f "
                                             r"exists only when .*hexapod_controller\(sensor_delay=True\)"):
        hexapod_controller().set_param("*.sensors.delay_f", 0.01)
    g = hexapod_controller(sensor_delay=True)
    g.set_param("*.sensors.delay_f", 0.01)
    assert g.find("R3.sensors").values["delay_f"] == 0.01
    with pytest.raises(ParameterError, match=r"block 's' has no parameter 'delay_f': it exists only when .*"
                                             r"YuSensoryNeurons\(delay_line=True\)"):
        YuSensoryNeurons("s").set(delay_f=0.01)
