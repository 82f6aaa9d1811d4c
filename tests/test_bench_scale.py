"""benchmarks/bench_scale.py's C reference and Drake peer compute the Yu Y5 equations (nothing is timed here)."""

from __future__ import annotations

import importlib.util
import shutil
import sys

import numpy as np
import pytest
from scipy.integrate import solve_ivp


def _load_bench_scale():
    """benchmarks/ is a folder of scripts, not part of the installed package: loaded from its file."""
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "benchmarks" / "bench_scale.py"
    spec = importlib.util.spec_from_file_location("bench_scale", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up there
    spec.loader.exec_module(module)
    return module


bs = _load_bench_scale()

# Network 0: Yu Table 1. Network 1: other values in every slot (and another start), so a parameter read
# from the wrong place in the per-network array shows.
PARAMS = np.array([[0.1, 4.0, 0.4 * np.pi, 0.8 * np.pi, 0.8 * np.pi, 0.1, 0.1, 0.1, 0.1],
                   [0.2, 2.0, 0.5 * np.pi, 1.0 * np.pi, 0.9 * np.pi, 0.2, 0.15, 0.05, 0.12]])
X0 = np.array([-1.0, 0.0, 0.5, 0.0, -0.5, 0.0, 1.0, 0.2, -0.3, 0.1, 0.4, -0.2])


def y5(_t: float, s: np.ndarray, params: np.ndarray) -> np.ndarray:
    """Yu Y5 written out per network and neuron (independent of the benchmark's vectorised rhs)."""
    d = np.empty_like(s)
    for i, (eps, b, w1, w2, w3, k12, k13, k23, k32) in enumerate(params):
        x1, y1, x2, y2, x3, y3 = s[6 * i: 6 * i + 6]
        drive = -4.0 * x1 * y1
        u = (0.0, k12 * (drive - y2) + k32 * (y3 - y2), k13 * (drive - y3) + k23 * (y2 - y3))
        for j, (x, y, w) in enumerate(((x1, y1, w1), (x2, y2, w2), (x3, y3, w3))):
            d[6 * i + 2 * j] = y
            d[6 * i + 2 * j + 1] = -eps * (b * x * x - 1.0) * y - w * w * x + u[j]
    return d


@pytest.mark.slow
@pytest.mark.skipif(shutil.which("gcc") is None and shutil.which("cc") is None, reason="no C compiler")
def test_c_reference_matches_solve_ivp(tmp_path):
    """RK4 at 1 ms for 1 s against solve_ivp (RK45, rtol 1e-10, atol 1e-12) at every step.

    Measured: max |C - solve_ivp| = 6.1e-11, which is solve_ivp's own error (at rtol 1e-12 the difference
    falls to 4e-12); the RK4 error itself is ~2e-12 (1 ms against 0.5 ms steps differ by 2.1e-12). The
    tolerance 1e-9 leaves a 16x margin; a wrong term or parameter moves the trajectory by > 1e-3.
    """
    ref = bs.CReference(tmp_path)
    out = ref.run(PARAMS, X0, steps=1000)
    assert out.shape == (1001, 12)
    assert np.array_equal(out[0], X0)
    sol = solve_ivp(y5, (0.0, 1.0), X0, method="RK45", rtol=1e-10, atol=1e-12,
                    t_eval=1e-3 * np.arange(1001), args=(PARAMS,))
    assert sol.success
    assert np.max(np.abs(out - sol.y.T)) < 1e-9


def test_benchmark_rhs_and_layout():
    """The vectorised RHS the peers use is the written-out one; initial state and parameter rows are Yu's."""
    n = 6
    params = bs.parameters(n)
    assert params.shape == (n, bs.NP_PER_NET)
    s = np.random.default_rng(1).normal(size=6 * n)
    np.testing.assert_allclose(bs.rhs(s), y5(0.0, s, params), rtol=0, atol=1e-13)
    assert bs.initial_state(n)[:6].tolist() == [-1.0, 0.0, 0.5, 0.0, -0.5, 0.0]
    assert bs.columns(2)[:3] == ["n0.z1.x", "n0.z1.y", "n0.z2.x"]
    assert bs.horizon_for(1800) == 20.0 and bs.horizon_for(18000) == 2.0


@pytest.mark.skipif(importlib.util.find_spec("pydrake") is None, reason="drake not installed")
@pytest.mark.parametrize("peer", [bs.DrakeSymbolic, bs.DrakeNumpy])
def test_drake_derivative_is_the_rhs(peer):
    """The 18-neuron Drake system's time derivative at the initial state is the analytic RHS."""
    n = 6
    system = peer().system(n)
    context = system.CreateDefaultContext()
    x0 = bs.initial_state(n)
    context.SetContinuousState(x0)
    derivative = system.EvalTimeDerivatives(context).CopyToVector()
    np.testing.assert_allclose(derivative, y5(0.0, x0, bs.parameters(n)), rtol=0, atol=1e-14)
    # and away from the initial state (where every y is 0 and the coupling terms vanish)
    s = np.random.default_rng(2).normal(size=6 * n)
    context.SetContinuousState(s)
    np.testing.assert_allclose(system.EvalTimeDerivatives(context).CopyToVector(), y5(0.0, s, bs.parameters(n)),
                               rtol=0, atol=1e-13)


def test_runners_are_timed_round_robin_with_one_warm_up_each():
    """Round i of every runner before round i + 1 of any; warm-up only where asked; the first output checked;
    a runner whose budget is used stops repeating (budget -1: used before any timed run)."""
    calls = []

    def job(name, warmup=True, budget=float("inf")):
        return bs.Job(name, 1, lambda: calls.append(name) or name, lambda out: len(out) * 0.5,
                      budget=budget, warmup=warmup)

    jobs = [job("c"), job("cpg"), job("peer", warmup=False), job("broke", warmup=False, budget=-1.0)]
    bs.interleaved(jobs, repeat=3)
    assert calls == ["c", "cpg"] + ["c", "cpg", "peer"] * 3
    assert [len(j.times) for j in jobs] == [3, 3, 3, 0]
    assert [j.diff for j in jobs] == [0.5, 1.5, 2.0, None]
