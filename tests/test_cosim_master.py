"""The co-simulation master's fast paths: the step on a worker thread, the committing C step, and the
plant's compiled readout and force-based servos -- each checked against the plain path it replaces."""

from __future__ import annotations

import os
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

from cpgsim.cli import catalog
from cpgsim.components.basic import Gain, Integrator
from cpgsim.components.core import CoSimBlock
from cpgsim.components.graph import Graph
from cpgsim.harness.compile import compile_graph
from cpgsim.harness.native import NativeFunction
from cpgsim.harness.simulate import SimulationDiverged, Simulator
from cpgsim.robots.dart.plant import DartHexapod


class Pulses(CoSimBlock):
    """A black box emitting a 3-vector toe force: a standing load with 60 N forward pushes (an obstacle)."""

    def declare(self) -> None:
        self.add_output("force", 3, "N")

    def setup(self, t0: float) -> None:
        self._t = t0

    def get_outputs(self) -> dict[str, np.ndarray]:
        push = 60.0 if 0.2 <= self._t % 0.5 < 0.24 else 0.0
        return {"force": np.array([0.0, push, 6.0])}

    def set_inputs(self, values) -> None:
        pass

    def do_step(self, t: float, dt: float) -> None:
        self._t = t + dt


def _os_threads() -> int:
    return len(os.listdir("/proc/self/task")) if Path("/proc/self/task").exists() else -1


def _leg_with_pulses() -> Graph:
    leg = catalog.load_graph("leg")
    g = Graph("leg_loop")
    g.add(leg)
    g.add(Pulses("obstacle"))
    force_inputs = [name for name, port in leg.inputs.items() if port.unit == "N" and port.size == 3]
    assert force_inputs, f"the leg graph has no 3-vector force input: {list(leg.inputs)}"
    g.connect("obstacle.force", f"leg.{force_inputs[0]}")
    return g


def test_threaded_step_gives_bit_identical_results_and_stops_its_thread():
    """The Yu leg driven by a black box: the step on a worker thread and on the caller's thread agree
    exactly (same C function, same buffers), and no thread outlives the run."""
    runs, threads = {}, {}
    for threaded in (False, True):
        sim = Simulator(_leg_with_pulses(), step_thread=threaded)
        threads[threaded] = _os_threads()  # after the first run's lazy library threads exist
        runs[threaded] = sim.run(3.0)
        assert type(sim._bound).__name__ == ("ThreadedStep" if threaded else "BoundStep")
    # no thread of the run outlives it (<=: a thread of an earlier test, e.g. a results writer or a library's
    # pool, may end meanwhile; seen once in a fresh-clone CI run: 19 after, 20 before)
    assert _os_threads() <= threads[True]
    a, b = runs[False], runs[True]
    assert a.columns == b.columns
    assert np.array_equal(a.data, b.data)
    assert np.ptp(a["obstacle.force"][:, 1]) == 60.0  # the pushes reached the record


def test_step_thread_is_off_by_default_even_for_large_steps(monkeypatch):
    """The worker thread's hand-off busy-waits and made loaded machines 2-7x slower: never the default,
    not even for the six-leg controller's step (the size that used to switch it on)."""
    from cpgsim.components.yu.leg import hexapod_controller
    from cpgsim.harness.simulate import NATIVE_AUTO_MAX_INSTRUCTIONS

    sim = Simulator(_leg_with_pulses())
    sim.run(0.05)
    assert type(sim._bound).__name__ == "BoundStep"
    assert not Simulator(hexapod_controller())._use_step_thread()
    assert compile_graph(hexapod_controller(), grouping="flat").step.n_instructions() > NATIVE_AUTO_MAX_INSTRUCTIONS


def test_step_thread_is_the_argument_and_the_results_say_which_ran(monkeypatch):
    """``step_thread`` decides (the environment variable that once overrode it is not read); both give the
    same numbers, and each run's results record which path ran."""
    runs = {}
    for threaded in (True, False):
        monkeypatch.setenv("CPGSIM_STEP_THREAD", "0" if threaded else "1")
        sim = Simulator(_leg_with_pulses(), step_thread=threaded)
        res = sim.run(0.05)
        assert type(sim._bound).__name__ == ("ThreadedStep" if threaded else "BoundStep")
        assert res.meta["execution"]["step_thread"] is threaded and res.meta["execution"]["step"] == "C"
        runs[threaded] = res.data
    assert np.array_equal(runs[True], runs[False])


@pytest.mark.parametrize("threaded", [False, True])
def test_divergence_in_a_cosimulation_keeps_partial_results(threaded):
    """x' = 2000 x overflows after about 0.35 s: the committing step refuses the non-finite state, the
    master names it and hands back the rows up to the last finite one."""
    g = Graph("blowup")
    g.add(Integrator("x", x0=1.0))
    g.add(Gain("k", k=2000.0, out_unit="1/s"))
    g.add(Pulses("box"))
    g.connect("x.y", "k.u")
    g.connect("k.y", "x.u")
    with pytest.raises(SimulationDiverged, match=r"state x\.x") as info:
        Simulator(g, step_thread=threaded).run(1.0)
    res = info.value.results
    assert not res.complete
    assert 0.3 < res.time[-1] < 0.4
    assert np.all(np.isfinite(res["x.y"]))


def test_native_function_matches_casadi_and_checks_its_buffers():
    x = ca.SX.sym("x", 3)
    fn = ca.Function("f", [x], [ca.sin(x) * x[0], ca.sumsqr(x)])
    a = np.array([0.3, -1.2, 2.5])
    s, q = np.zeros(3), np.zeros(1)
    NativeFunction(fn, [a], [s, q])()
    ref = fn(a)
    assert np.array_equal(s, np.asarray(ref[0]).ravel())
    assert q[0] == float(ref[1])
    with pytest.raises(ValueError, match="size 1"):
        NativeFunction(fn, [a], [s, np.zeros(2)])


def test_force_servo_equals_moving_rest_position_servo():
    """The plant's servo (spring at rest 0 plus the force kp * q_target) against DART's spring with its
    rest position moved to the target: the same law, so the same motion to rounding."""
    rng = np.random.default_rng(11)
    targets = [DartHexapod().q0 + rng.uniform(-0.25, 0.25, 18) for _ in range(4)]
    final = []
    for moving_rest in (False, True):
        robot = DartHexapod()
        robot.setup(0.0)
        if moving_rest:
            def rest_servo(q_target, velocity, r=robot) -> None:  # the forces stay 0, the springs move
                for joint, q in zip(r.model.joints, q_target, strict=True):
                    joint.setRestPosition(0, float(q))
                r._forces[:] = 0.0
            robot._apply_servo = rest_servo
        for k in range(400):
            robot.set_inputs({"q_target": targets[k // 100]})
            robot.do_step(k * 1e-3, 1e-3)
        final.append(robot.model.skeleton.getPositions())
    assert np.max(np.abs(final[0] - final[1])) < 1e-9


class Stopper(CoSimBlock):
    """y = u + t (direct feedthrough); asks to end the run when a step reaches ``t_stop``; any input
    or step after that is a failure (the master must not touch it again)."""

    def __init__(self, name: str, t_stop: float, within: bool = False) -> None:
        self.t_stop, self.within = t_stop, within
        super().__init__(name)

    def declare(self) -> None:
        self.add_input("u", default=0.0)
        self.add_output("y")
        self.feedthrough = {"y": {"u"}}

    def setup(self, t0: float) -> None:
        self._t, self._u, self._done = t0, 0.0, False

    def get_outputs(self) -> dict[str, np.ndarray]:
        return {"y": np.array([self._u + self._t])}

    def set_inputs(self, values) -> None:
        if self._done:
            raise RuntimeError("inputs set after the stop request")
        self._u = float(np.asarray(values["u"]).ravel()[0])

    def do_step(self, t: float, dt: float) -> None:
        from cpgsim.harness.errors import StopRequested

        if self._done:
            raise RuntimeError("stepped after the stop request")
        if t + dt >= self.t_stop - 1e-12:
            self._done = True
            if self.within:  # stopped inside the step: last successful time t
                raise StopRequested("stopper: no further", t)
            self._t = t + dt
            raise StopRequested("stopper: reached the end", t + dt)
        self._t = t + dt


@pytest.mark.parametrize("within", [False, True])
def test_a_block_asking_to_stop_ends_the_run_cleanly(within):
    """Generic (no FMU): the stop time is the last row, the rows before are all there, the block is
    not given inputs or stepped again (even with direct feedthrough), the other blocks' columns too."""
    from cpgsim.components.basic import Constant

    g = Graph("g")
    g.add(Constant("c", value=2.0))
    g.add(Stopper("s", 0.5, within))
    g.connect("c.y", "s.u")
    from cpgsim.harness.simulate import simulate

    res = simulate(g, 2.0, dt=0.1)
    assert res.complete and res.meta["stopped_by"]["block"] == "s"
    end = 0.4 if within else 0.5
    assert res.time[-1] == pytest.approx(end) and len(res.time) == round(end / 0.1) + 1
    np.testing.assert_allclose(res["s.y"], 2.0 + res.time, atol=1e-12)
    assert res.meta["stopped_by"]["time"] == pytest.approx(0.4 if within else 0.5)
