"""Scale benchmark: cost per neuron-step with size, against a hand-written C RK4 (the limit) and peers.

Workload: N copies of the Yu 2019 Y5 leader-follower Van der Pol network (3 neurons each; Table 1:
eps 0.1, b 4, omega (0.4 pi, 0.8 pi, 0.8 pi), k 0.1; leader starts at (-1, 0), followers at (0.5, 0)
and (-0.5, 0)), N = 6, 60, 600, 6000 networks (18 ... 18,000 neurons), fixed step dt = 1 ms, every
state recorded at every step. The horizon is 20 s (20,000 steps) up to 1,800 neurons and 2 s at 18,000
(20 s of 36,000 states would be 5.8 GB); sizes are compared by *cost per neuron-step*,
wall / (steps x neurons), so the horizons need not be equal.

Runners, all set up and compiled first (outside the timing; cpgsim's one-time costs are printed), then
timed *interleaved*: round ``i`` runs every runner once before round ``i + 1`` (``--repeat`` rounds,
default 5; medians), so a change of the machine's load hits all runners alike. The C reference and
cpgsim run once untimed before the first round (first-touch page faults); a peer's probe runs warm it.
With the default ``--peer-budget`` of 4 s the whole benchmark takes about 3 minutes here (187 s on
2026-12-02 at load 2.6-3.8).

* **C reference** (``benchmarks/reference_rk4.c``, gcc -O2, ctypes): RK4 at 1 ms written by hand, every
  state stored into a ``np.empty`` buffer the caller allocates (first-touch page faults are paid, as in
  cpgsim's result buffers). The limit cpgsim is measured against (target: cpgsim within 2x of it).
* **cpgsim**, twice: ``Simulator(networks(n), dt=1e-3, backend=--backend, record=["*.z?.x", "*.z?.y"])``
  (the six states per network the C reference stores) and ``Simulator(networks(n), dt=1e-3)`` with its
  default recording (every signal: the six states and three coupling signals per network, 1.5x the
  bytes; target: within 1.3x of the C reference); ``.prepare()`` untimed, ``.run(T)`` timed. Its columns
  are checked against the C reference (same RK4, same operation order: agreement is to rounding, or
  exact). Its one-time costs are printed separately: ``Simulator(...)`` (graph compile) and ``.prepare()``
  (C generation + gcc), by default with a fresh
  (cold) build cache; ``--warm-cache`` uses the usual one.
* **Peers** (optional, ``pip install -e '.[bench]'``; target: cpgsim >= 10x ahead of the fastest):

  - ``drake symbolic RK3``: pydrake ``SymbolicVectorSystem`` of the same equations (state = output).
  - ``drake numpy RK3``: a pydrake ``LeafSystem`` whose ``DoCalcTimeDerivatives`` evaluates the same RHS
    vectorised with numpy over all networks.
    Both: ``SimulatorConfig(integration_scheme="runge_kutta3", max_step_size=1e-3,
    use_error_control=False)`` applied with ``ApplySimulatorConfig`` -- fixed-step RK3 at 1 ms (Drake has
    no RK4: "runge_kutta4" is an unknown scheme; RK3 takes 3 RHS evaluations a step against RK4's 4,
    which favours Drake). Every state is recorded every step by a ``VectorLogSink``
    (``LogVectorOutput(..., publish_period=1e-3)``); a timed run resets the context and clears the log,
    then ``AdvanceTo(T)`` and reads ``log.data()``.
  - ``pycollimator RK4 update``: a pycollimator ``LeafSystem`` whose discrete state is advanced by one
    RK4 step of 1 ms in a periodic update (``declare_periodic_update``, period = offset = 1 ms), RHS in
    ``jax.numpy``: the same numerical work as cpgsim, and pycollimator's fastest configuration found.
  - ``pycollimator dopri5``: its own integrator, a continuous-state ``LeafSystem`` (same RHS) with
    ``ode_solver_method="dopri5"``, ``rtol=1e-6``, ``atol=1e-8``, ``max_minor_step_size=1e-3``: the
    steps are capped at 1 ms (at that size the error estimate is far below the tolerances), 6 RHS
    evaluations a step (FSAL), results saved at every minor step: the samples are the 1 ms grid (checked).
    (``max_major_step_length=1e-3`` makes pycollimator 2.2.0 fail with "step size ... approaching the
    difference between two adjacent floating-point numbers" at t = 0.01.)
    Both: JAX backend, float64, ``recorded_signals`` = the full state, ``return_context=False``,
    ``max_major_steps = steps + 5``; the simulation ``Simulator(...).advance_to(T, context)`` is
    ``jax.jit``-ed and compiled ahead (``.lower(context).compile()``) outside the timing; a timed run is
    the compiled call plus ``results_data.finalize()``. ``buffer_length`` is round(sqrt(2 steps)):
    pycollimator 2.2.0 hands its whole result buffer to a host callback at every step and ``np.append``-s it
    to the rows kept so far whenever it fills, so a buffer holding the whole run (its documented advice)
    costs O(steps^2) (9 s instead of 0.4 s for 20 s of 18 neurons) and a small one O(steps^2 / length);
    sqrt(2 steps) was the best of those tried (600 networks, 5,000 steps: 25 / 50 / 100 / 200 rows ->
    434 / 284 / 178 / 237 ns per neuron-step; 60 networks, 20,000 steps: 30 / 100 / 300 / 1000 -> 1389 /
    595 / 538 / 809). The cost still grows with the horizon: a shortened (capped) run
    flatters pycollimator's cost per neuron-step.

Peers at large sizes: a 10-step warm-up, then runs of 100, 1,000 ... steps while they take under a quarter
of ``--peer-budget``, estimate a peer's cost; when a
full-horizon run would exceed half of ``--peer-budget`` seconds the peer runs a shorter horizon (printed:
this flatters pycollimator, whose cost per step grows with the horizon), and at
sizes above 1,800 neurons a peer whose full-horizon run is estimated above ``--peer-skip`` seconds is
skipped ("skipped (est. X s)"). Peer runs stop repeating once they have used ``--peer-budget``.
Every runner uses one core (for JAX this was checked: process CPU time = wall time).

    python benchmarks/bench_scale.py [--sizes 6,60,600,6000] [--backend native] [--repeat 5]
                                     [--no-peers] [--json FILE]
"""

from __future__ import annotations

import argparse
import ctypes
import importlib.util
import json
import math
import os
import shutil
import statistics
import subprocess
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent

from cpgsim.components.graph import Graph  # noqa: E402
from cpgsim.components.networks import leader_follower_network  # noqa: E402

DT = 1e-3
EPS, B, K = 0.1, 4.0, 0.1
OMEGA = (0.4 * math.pi, 0.8 * math.pi, 0.8 * math.pi)
START = (-1.0, 0.0, 0.5, 0.0, -0.5, 0.0)  # x1, y1, x2, y2, x3, y3
NP_PER_NET = 9  # eps, b, omega1, omega2, omega3, k12, k13, k23, k32 (reference_rk4.c)
FULL_HORIZON, LARGE_HORIZON, LARGE_ABOVE = 20.0, 2.0, 1800  # neurons above LARGE_ABOVE: LARGE_HORIZON
WARM_STEPS = 10  # a peer's first (warm-up) run; its cost is then estimated from runs 10x, 100x longer
TARGET_C, TARGET_DEFAULT, TARGET_PEER = 2.0, 1.3, 10.0
TARGET_CALL = 1.5
"""Issue 46, item 4: the whole default call within 1.5x of the C loop."""
DEFAULT_SIZES = "6,60,600,6000"
INSTALL_HINT = "pip install -e '.[bench]'"


# -- the workload ---------------------------------------------------------------------------------
def networks(n: int) -> Graph:
    """``n`` Yu Y5 networks ``n0 .. n{n-1}`` (Table 1 defaults, leader start (-1, 0)) in one graph."""
    g = Graph(f"networks{n}", f"{n} leader-follower networks (Yu Y5)")
    for i in range(n):
        g.add(leader_follower_network(f"n{i}", eps=EPS, b=B, omega=OMEGA, k=K, leader_start=START[:2],
                                      follower_starts=(START[2:4], START[4:6])))
    return g


def columns(n: int) -> list[str]:
    """cpgsim's recorded columns in the reference's state order (per network x1, y1, x2, y2, x3, y3)."""
    return [f"n{i}.z{j}.{v}" for i in range(n) for j in (1, 2, 3) for v in ("x", "y")]


def initial_state(n: int) -> np.ndarray:
    return np.tile(np.array(START), n)


def parameters(n: int) -> np.ndarray:
    """Per-network parameter rows for the C reference: eps, b, omega1..3, k12, k13, k23, k32."""
    return np.tile(np.array([EPS, B, *OMEGA, K, K, K, K]), (n, 1))


def rhs(s: np.ndarray, xp=np) -> np.ndarray:
    """Yu Y5 right-hand side of all networks, vectorised (``xp``: numpy or jax.numpy); s = (6 n,)."""
    s = s.reshape(-1, 3, 2)
    x, y = s[:, :, 0], s[:, :, 1]
    drive = -4.0 * x[:, 0] * y[:, 0]
    u2 = K * (drive - y[:, 1]) + K * (y[:, 2] - y[:, 1])
    u3 = K * (drive - y[:, 2]) + K * (y[:, 1] - y[:, 2])
    u = xp.stack([xp.zeros_like(drive), u2, u3], axis=1)
    dy = -EPS * (B * (x * x) - 1.0) * y - xp.asarray(np.square(OMEGA)) * x + u
    return xp.stack([y, dy], axis=2).reshape(-1)


def horizon_for(neurons: int, large: float = LARGE_HORIZON) -> float:
    return FULL_HORIZON if neurons <= LARGE_ABOVE else large


# -- C reference ------------------------------------------------------------------------------------
class CReference:
    """``reference_rk4.c`` compiled with gcc -O2 into a temporary directory, called through ctypes."""

    def __init__(self, workdir: Path) -> None:
        cc = os.environ.get("CC") or shutil.which("gcc") or shutil.which("cc")
        if cc is None:
            raise RuntimeError("no C compiler (gcc) for the C reference")
        lib = workdir / "libreference_rk4.so"
        proc = subprocess.run([cc, "-O2", "-shared", "-fPIC", str(HERE / "reference_rk4.c"), "-o", str(lib)],
                              capture_output=True, text=True)
        if proc.returncode != 0:
            raise RuntimeError(f"gcc failed on reference_rk4.c: {proc.stderr.strip()[:500]}")
        self._lib = ctypes.CDLL(str(lib))
        vec = np.ctypeslib.ndpointer(np.float64, flags="C_CONTIGUOUS")
        self._lib.y5_rk4.argtypes = [ctypes.c_long, vec, vec, ctypes.c_double, ctypes.c_long, vec]
        self._lib.y5_rk4.restype = ctypes.c_int

    def run(self, params: np.ndarray, x0: np.ndarray, steps: int, dt: float = DT) -> np.ndarray:
        """States at every step, ``(steps + 1, 6 n)``, in a buffer allocated here with ``np.empty``."""
        params = np.ascontiguousarray(params, dtype=np.float64)
        x0 = np.ascontiguousarray(x0, dtype=np.float64)
        n = params.shape[0]
        out = np.empty((steps + 1, 6 * n))
        self._lib.y5_rk4(n, params, x0, dt, steps, out)
        return out


# -- peers ------------------------------------------------------------------------------------------
class Peer:
    """A peer simulator: ``setup(n)`` once, ``prepare(steps)`` (untimed), ``run(steps)`` -> (steps+1, 6 n)."""

    name = "peer"
    module = ""
    package = ""

    @classmethod
    def installed(cls) -> bool:
        return importlib.util.find_spec(cls.module) is not None

    def setup(self, n: int) -> None:
        raise NotImplementedError

    def prepare(self, steps: int) -> None:
        pass

    def run(self, steps: int) -> np.ndarray:
        raise NotImplementedError


class _Drake(Peer):
    module, package = "pydrake", "drake"

    def system(self, n: int):
        raise NotImplementedError

    def setup(self, n: int) -> None:
        from pydrake.systems.analysis import ApplySimulatorConfig, Simulator, SimulatorConfig
        from pydrake.systems.framework import DiagramBuilder
        from pydrake.systems.primitives import LogVectorOutput

        builder = DiagramBuilder()
        plant = builder.AddSystem(self.system(n))
        self._logger = LogVectorOutput(plant.get_output_port(0), builder, publish_period=DT)
        self._diagram = builder.Build()
        self._sim = Simulator(self._diagram)
        ApplySimulatorConfig(SimulatorConfig(integration_scheme="runge_kutta3", max_step_size=DT,
                                             use_error_control=False), self._sim)
        self._x0 = initial_state(n)

    def run(self, steps: int) -> np.ndarray:
        ctx = self._sim.get_mutable_context()
        ctx.SetTime(0.0)
        ctx.SetContinuousState(self._x0)
        self._logger.FindMutableLog(ctx).Clear()
        self._sim.Initialize()
        self._sim.AdvanceTo(steps * DT)
        return self._logger.FindLog(ctx).data().T


class DrakeSymbolic(_Drake):
    name = "drake symbolic RK3"

    def system(self, n: int):
        from pydrake.symbolic import MakeVectorContinuousVariable
        from pydrake.systems.primitives import SymbolicVectorSystem

        s = MakeVectorContinuousVariable(6 * n, "s")
        return SymbolicVectorSystem(state=s, dynamics=drake_dynamics(s), output=s)


class DrakeNumpy(_Drake):
    name = "drake numpy RK3"

    def system(self, n: int):
        return drake_numpy_system(n)


def drake_dynamics(s) -> list:
    """The same equations as symbolic expressions of pydrake variables ``s`` (6 n of them)."""
    out = []
    w2 = [w * w for w in OMEGA]
    for i in range(len(s) // 6):
        x1, y1, x2, y2, x3, y3 = s[6 * i: 6 * i + 6]
        drive = -4.0 * x1 * y1
        u = (0.0, K * (drive - y2) + K * (y3 - y2), K * (drive - y3) + K * (y2 - y3))
        for x, y, w, ui in ((x1, y1, w2[0], u[0]), (x2, y2, w2[1], u[1]), (x3, y3, w2[2], u[2])):
            out += [y, -EPS * (B * (x * x) - 1.0) * y - w * x + ui]
    return out


def drake_numpy_system(n: int):
    """A pydrake LeafSystem with 6 n continuous states, derivatives from :func:`rhs` (numpy), output = state."""
    from pydrake.systems.framework import BasicVector, LeafSystem

    class Y5Networks(LeafSystem):
        def __init__(self) -> None:
            super().__init__()
            self.DeclareContinuousState(6 * n)
            self.DeclareVectorOutputPort("state", BasicVector(6 * n), self._output)

        def DoCalcTimeDerivatives(self, context, derivatives) -> None:  # noqa: N802 (Drake's name)
            s = context.get_continuous_state_vector().CopyToVector()
            derivatives.get_mutable_vector().SetFromVector(rhs(s))

        def _output(self, context, output) -> None:
            output.SetFromVector(context.get_continuous_state_vector().CopyToVector())

    return Y5Networks()


class _Collimator(Peer):
    module, package = "collimator", "pycollimator"
    ode_solver_method = "dopri5"

    def leaf(self, n: int):
        raise NotImplementedError

    def setup(self, n: int) -> None:
        import collimator  # noqa: F401 (enables float64 in JAX)

        self._system = self.leaf(n)
        self._context = self._system.create_context()
        self._compiled: dict[int, Callable] = {}

    def prepare(self, steps: int) -> None:
        if steps in self._compiled:
            return
        import jax
        from collimator import ODESolver, Simulator, SimulatorOptions

        t_end = steps * DT
        options = SimulatorOptions(math_backend="jax", enable_tracing=True, ode_solver_method=self.ode_solver_method,
                                   rtol=1e-6, atol=1e-8, max_minor_step_size=DT, max_major_steps=steps + 5,
                                   buffer_length=collimator_buffer_length(steps), save_time_series=True,
                                   recorded_signals={"state": self._system.output_ports[0]}, return_context=False)
        sim = Simulator(self._system, ode_solver=ODESolver(self._system, options=options.ode_options), options=options)
        self._system.cache_enabled = True  # as collimator.simulate() does for the run

        def advance(context):
            return sim.advance_to(t_end, context).results_data

        self._compiled[steps] = jax.jit(advance).lower(self._context).compile()

    def run(self, steps: int) -> np.ndarray:
        times, outputs = self._compiled[steps](self._context).finalize()
        states = np.asarray(outputs["state"])
        # dopri5 saves the last minor step's end twice; check the rows are the 1 ms grid
        grid = DT * np.arange(steps + 1)
        if len(times) < steps + 1 or np.max(np.abs(np.asarray(times)[: steps + 1] - grid)) > 1e-9:
            raise RuntimeError(f"{self.name}: samples are not the 1 ms grid ({len(times)} samples for {steps} steps)")
        return states[: steps + 1]


def collimator_buffer_length(steps: int) -> int:
    """pycollimator's result buffer rows: sqrt(2 steps) balances its per-step and per-dump copies (docstring)."""
    return max(10, round(math.sqrt(2 * steps)))


class CollimatorRK4(_Collimator):
    name = "pycollimator RK4 update"

    def leaf(self, n: int):
        import jax.numpy as jnp
        from collimator import LeafSystem

        class Y5NetworksRK4(LeafSystem):
            """Discrete state advanced by one RK4 step of DT in a periodic update; output = state."""

            def __init__(self) -> None:
                super().__init__(name="y5_rk4")
                self.declare_discrete_state(shape=(6 * n,), default_value=initial_state(n))
                self.declare_periodic_update(self._step, period=DT, offset=DT)
                self.declare_output_port(self._output, requires_inputs=False)

            def _output(self, time, state, *inputs, **parameters):
                return state.discrete_state

            def _step(self, time, state, *inputs, **parameters):
                s, h = state.discrete_state, DT
                k1 = rhs(s, jnp)
                k2 = rhs(s + h / 2 * k1, jnp)
                k3 = rhs(s + h / 2 * k2, jnp)
                k4 = rhs(s + h * k3, jnp)
                return s + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)

        return Y5NetworksRK4()


class CollimatorDopri5(_Collimator):
    name = "pycollimator dopri5"

    def leaf(self, n: int):
        import jax.numpy as jnp
        from collimator import LeafSystem

        class Y5Networks(LeafSystem):
            def __init__(self) -> None:
                super().__init__(name="y5")
                self.declare_continuous_state(shape=(6 * n,), default_value=initial_state(n), ode=self._ode)
                self.declare_continuous_state_output()

            def _ode(self, time, state, *inputs, **parameters):
                return rhs(state.continuous_state, jnp)

        return Y5Networks()


PEERS: tuple[type[Peer], ...] = (DrakeSymbolic, DrakeNumpy, CollimatorRK4, CollimatorDopri5)


# -- measuring --------------------------------------------------------------------------------------
def max_abs_diff(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.max(np.abs(a - b))) if a.size else 0.0


def row(name: str, steps: int, runs: int, wall: float, neurons: int, c_wall_per: float | None,
        diff: float | None, note: str = "") -> dict:
    per = wall / (steps * neurons)
    return {"runner": name, "horizon_s": steps * DT, "steps": steps, "runs": runs, "median_wall_s": wall,
            "ns_per_neuron_step": per * 1e9, "ratio_vs_c": per / c_wall_per if c_wall_per else None,
            "max_abs_diff_vs_c": diff, "note": note}


@dataclass
class Job:
    """One runner of a size, set up and compiled: ``run()`` is what is timed; ``check(out)`` -> max |x - C|."""

    name: str
    steps: int
    run: Callable[[], object]
    check: Callable[[object], float]
    budget: float = math.inf  # seconds of timed runs after which this runner stops repeating
    warmup: bool = True  # one untimed run first (a peer's probes have warmed it already)
    note: str = ""
    info: dict = field(default_factory=dict)
    times: list[float] = field(default_factory=list)
    diff: float | None = None


def interleaved(jobs: list[Job], repeat: int) -> None:
    """Time the jobs round-robin: run ``i`` of every job before run ``i + 1`` of any (so a change of the
    machine's load hits all runners alike), one untimed warm-up each first; a job stops repeating once its
    timed runs have used its ``budget``. Fills ``job.times`` and ``job.diff`` (from its first run).

    The warm-up matters: the first large allocation of a process is slow to fault in (the kernel finds and
    zeroes huge pages for it): measured here, the C reference's first 2 s run at 18,000 neurons took 1.7 s
    and the next four 0.63-0.74 s; cpgsim's likewise."""
    for job in jobs:
        if job.warmup:
            job.diff = job.check(job.run())  # first-touch page faults; the accuracy check
    for _ in range(repeat):
        for job in jobs:
            if sum(job.times) > job.budget:
                continue
            t0 = time.perf_counter()
            out = job.run()
            job.times.append(time.perf_counter() - t0)
            if job.diff is None:
                job.diff = job.check(out)
            del out


def call_job(n: int, steps: int, c_out: np.ndarray) -> Job:
    """The whole default call a user makes, timed as one: ``Simulator(g).run(T)`` on a built graph (default
    backend and recording; the graph compile and the compile-cache load inside the timing, the C build warm
    after the untimed first run). Issue 46, item 4: within 1.5x of the C loop at 600 networks."""
    from cpgsim.harness.simulate import Simulator

    graph = networks(n)

    def check(res) -> float:
        return max(max_abs_diff(np.asarray(res[col]), c_out[:, j]) for j, col in enumerate(columns(n)))

    return Job("cpgsim Simulator(g).run(T), whole call", steps, lambda: Simulator(graph, dt=DT).run(steps * DT), check)


def cpgsim_job(n: int, steps: int, backend: str, c_out: np.ndarray, default_recording: bool) -> tuple[Job, dict]:
    """cpgsim's simulator, built and prepared (timed separately: the returned dict); the job runs ``T``.

    ``default_recording``: ``Simulator(g)`` as a user calls it (every signal recorded: per network the six
    states and three coupling signals); else ``record=`` the six states, what the C reference stores."""
    from cpgsim.harness.simulate import Simulator

    graph = networks(n)
    t0 = time.perf_counter()
    record = None if default_recording else ["*.z?.x", "*.z?.y"]
    sim = Simulator(graph, dt=DT, backend=backend, record=record)
    t1 = time.perf_counter()
    sim.prepare()
    t2 = time.perf_counter()

    def check(res) -> float:
        return max(max_abs_diff(np.asarray(res[col]), c_out[:, j]) for j, col in enumerate(columns(n)))

    label = "default recording" if default_recording else "states recorded"
    job = Job(f"cpgsim ({backend}, {label})", steps, lambda: sim.run(steps * DT), check)
    return job, {"construct_s": t1 - t0, "prepare_s": t2 - t1}


def peer_job(cls: type[Peer], n: int, steps_full: int, budget: float, skip_limit: float,
             c_out: np.ndarray) -> Job | dict:
    """Set up, probe, maybe cap the horizon of, and compile one peer: its job, or why it does not run."""
    neurons = 3 * n
    peer = cls()
    t0 = time.perf_counter()
    peer.setup(n)
    setup_s = time.perf_counter() - t0
    per_step, probe = 0.0, 0
    while probe < steps_full:  # 10 steps (first-call costs), then 10x longer runs while they are cheap
        nxt = min(steps_full, WARM_STEPS if probe == 0 else probe * 10)
        if probe and (per_step * steps_full <= budget or per_step * nxt > budget / 4):
            break  # the full run fits the budget, or a longer probe would cost too much
        peer.prepare(nxt)
        t0 = time.perf_counter()
        peer.run(nxt)
        per_step, probe = (time.perf_counter() - t0) / nxt, nxt
    est_full = per_step * steps_full
    info = {"setup_s": setup_s, "est_full_s": est_full}
    if neurons > LARGE_ABOVE and est_full > skip_limit:
        info["skipped"] = f"skipped (est. {est_full:.0f} s)"
        return info
    steps, note = steps_full, ""
    if est_full > budget / 2:  # half: a peer's cost per step can grow with the horizon (pycollimator's does)
        steps = max(probe, int(budget / 2 / per_step) // 100 * 100)
        note = f"capped: {steps * DT:g} s of {steps_full * DT:g} s (est. {est_full:.0f} s for all)"
    t0 = time.perf_counter()
    peer.prepare(steps)
    info["prepare_s"] = time.perf_counter() - t0

    def check(out) -> float:
        if out.shape != (steps + 1, 6 * n):
            raise RuntimeError(f"{cls.name}: recorded {out.shape}, expected {(steps + 1, 6 * n)}")
        return max_abs_diff(out, c_out[: steps + 1])

    return Job(cls.name, steps, lambda: peer.run(steps), check, budget=budget, warmup=False, note=note, info=info)


def versions() -> dict[str, str | None]:
    """Installed versions of what the figures depend on (peers' speed changes with their versions)."""
    from importlib import metadata

    out: dict[str, str | None] = {}
    for dist in ("cpgsim", "numpy", "casadi", "drake", "pycollimator", "jax", "jaxlib"):
        try:
            out[dist] = metadata.version(dist)
        except metadata.PackageNotFoundError:
            out[dist] = None
    return out


def fmt_time(s: float) -> str:
    return f"{s * 1e3:9.1f} ms" if s < 10 else f"{s:9.2f} s "


def print_table(rows: list[dict], cpgsim_ns: float) -> None:
    print(f"  {'runner':36s} {'horizon':>8s} {'runs':>4s} {'median wall':>12s} {'ns/neuron-step':>15s} "
          f"{'runner/C':>9s} {'peer/cpgsim':>11s} {'max|x - C|':>10s}")
    for r in rows:
        if "skipped" in r:
            print(f"  {r['runner']:36s} {r['skipped']}")
            continue
        lead = r["ns_per_neuron_step"] / cpgsim_ns if r.get("peer") else None
        r["peer_over_cpgsim"] = lead
        print(f"  {r['runner']:36s} {r['horizon_s']:6.1f} s {r['runs']:4d} {fmt_time(r['median_wall_s']):>12s} "
              f"{r['ns_per_neuron_step']:15.1f} {r['ratio_vs_c']:9.2f} "
              f"{(f'{lead:11.1f}' if lead is not None else '-'):>11s} {r['max_abs_diff_vs_c']:10.1e}"
              + (f"   {r['note']}" if r["note"] else ""))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", default=DEFAULT_SIZES, help="numbers of networks, comma-separated (3 neurons each)")
    ap.add_argument("--backend", default="native", choices=("native", "casadi", "auto"), help="cpgsim backend")
    ap.add_argument("--repeat", type=int, default=5, help="timed runs per runner, interleaved (median)")
    ap.add_argument("--peers", action=argparse.BooleanOptionalAction, default=None,
                    help="run Drake / pycollimator (default: those installed)")
    ap.add_argument("--peer-budget", type=float, default=4.0,
                    help="seconds one peer run may take before its horizon is shortened (and its repeats stop)")
    ap.add_argument("--peer-skip", type=float, default=120.0,
                    help=f"above {LARGE_ABOVE} neurons, skip a peer whose full run is estimated over this many s")
    ap.add_argument("--warm-cache", action="store_true",
                    help="use cpgsim's usual build cache (default: a fresh one, so the C build is timed cold)")
    ap.add_argument("--large-horizon", type=float, default=LARGE_HORIZON,
                    help=f"horizon in s above {LARGE_ABOVE} neurons (default {LARGE_HORIZON:g}; 20 s at 18,000 neurons "
                         "holds 5.8 GB of states per runner besides the C reference's copy: on a 24 GB machine "
                         "the peers' set-up ran out of memory, 2026-12-03)")
    ap.add_argument("--json", type=Path, help="also write the numbers to this JSON file")
    args = ap.parse_args()
    sizes = sorted({int(s) for s in args.sizes.split(",") if s.strip()})
    if not sizes or min(sizes) < 1:
        ap.error("--sizes: positive numbers of networks")

    peers: list[type[Peer]] = []
    if args.peers is not False:
        missing: list[str] = []
        for cls in PEERS:
            if cls.installed():
                peers.append(cls)
            elif cls.package not in missing:
                missing.append(cls.package)
        for package in missing:
            print(f"{package} not installed: {INSTALL_HINT}")

    report: dict = {"dt": DT, "backend": args.backend, "repeat": args.repeat, "cold_cache": not args.warm_cache,
                    "peer_budget_s": args.peer_budget, "peer_skip_s": args.peer_skip, "versions": versions(),
                    "sizes": [], "ratios": []}
    with tempfile.TemporaryDirectory(prefix="bench_scale_") as tmp:
        workdir = Path(tmp)
        if not args.warm_cache:
            os.environ["CPGSIM_CACHE"] = str(workdir / "cpgsim-cache")
        ref = CReference(workdir)
        print(f"Yu Y5 networks, RK4 at dt = {DT * 1e3:g} ms, every state recorded every step; cpgsim backend "
              f"{args.backend!r}; median of {args.repeat}; peers: {', '.join(c.name for c in peers) or 'none'}")
        for n in sizes:
            neurons = 3 * n
            horizon = horizon_for(neurons, args.large_horizon)
            steps = int(round(horizon / DT))
            print(f"\n== {n} networks = {neurons:,} neurons, horizon {horizon:g} s ({steps:,} steps) ==", flush=True)
            t_size = time.perf_counter()
            params, x0 = parameters(n), initial_state(n)
            c_out = ref.run(params, x0, steps)  # the reference states every runner is checked against
            jobs = [Job("C reference (gcc -O2)", steps, lambda: ref.run(params, x0, steps),  # noqa: B023
                        lambda out, ref_out=c_out: max_abs_diff(out, ref_out))]
            builds = {}
            for default_recording in (False, True):
                job, build = cpgsim_job(n, steps, args.backend, c_out, default_recording)
                jobs.append(job)
                builds[job.name] = build
            jobs.append(call_job(n, steps, c_out))
            built = "C build" + ("" if args.warm_cache else ", cold cache")
            built = "no C to build" if args.backend == "casadi" else built
            for name, build in builds.items():
                print(f"  {name} one-time cost: Simulator() {build['construct_s']:.2f} s (graph compile) + "
                      f"prepare() {build['prepare_s']:.2f} s ({built})")
                built = "C build, warm cache: the same step"
            skipped = []
            for cls in peers:
                print(f"  ... setting up {cls.name}", flush=True)
                job = peer_job(cls, n, steps, args.peer_budget, args.peer_skip, c_out)
                if isinstance(job, dict):
                    skipped.append({"runner": cls.name, "skipped": job["skipped"], "peer": True,
                                    "est_full_s": job["est_full_s"]})
                else:
                    jobs.append(job)
            t_setup = time.perf_counter() - t_size
            interleaved(jobs, args.repeat)
            t_runs = time.perf_counter() - t_size - t_setup
            print(f"  set-up of all runners {t_setup:.1f} s, interleaved runs {t_runs:.1f} s")
            c_per = statistics.median(jobs[0].times) / (steps * neurons)
            rows = []
            for k, job in enumerate(jobs):
                note = job.note or ("bit-exact vs C" if k in (1, 2, 3) and job.diff == 0 else "")
                r = row(job.name, job.steps, len(job.times), statistics.median(job.times), neurons, c_per,
                        job.diff, note)
                if k > 3:
                    r.update(peer=True, setup_s=job.info["setup_s"], prepare_s=job.info["prepare_s"])
                rows.append(r)
            rows += skipped
            build = builds[jobs[1].name]
            cpgsim_ns = rows[1]["ns_per_neuron_step"]
            del c_out, jobs
            print_table(rows, cpgsim_ns)
            ran = [r for r in rows if r.get("peer") and "skipped" not in r]
            fastest = min(ran, key=lambda r: r["ns_per_neuron_step"]) if ran else None
            ratio_c = rows[1]["ratio_vs_c"]
            ratio_default = rows[2]["ratio_vs_c"]
            ratio_call = rows[3]["ratio_vs_c"]
            ratio_peer = fastest["ns_per_neuron_step"] / cpgsim_ns if fastest else None
            report["sizes"].append({"networks": n, "neurons": neurons, "horizon_s": horizon, "steps": steps,
                                    "cpgsim_build": build, "cpgsim_builds": builds, "rows": rows})
            report["ratios"].append({"neurons": neurons, "cpgsim_over_c": ratio_c,
                                     "cpgsim_default_over_c": ratio_default, "cpgsim_call_over_c": ratio_call,
                                     "fastest_peer": fastest and
                                     fastest["runner"], "fastest_peer_over_cpgsim": ratio_peer})
        print()
        for r in report["ratios"]:
            met = "met" if r["cpgsim_over_c"] <= TARGET_C else "not met"
            print(f"RATIO cpgsim/C at {r['neurons']} neurons = {r['cpgsim_over_c']:.2f} "
                  f"(target <= {TARGET_C:g}: {met})")
        for r in report["ratios"]:
            met = "met" if r["cpgsim_default_over_c"] <= TARGET_DEFAULT else "not met"
            print(f"RATIO cpgsim default recording/C at {r['neurons']} neurons = {r['cpgsim_default_over_c']:.2f} "
                  f"(target <= {TARGET_DEFAULT:g}: {met})")
            met = "met" if r["cpgsim_call_over_c"] <= TARGET_CALL else "not met"
            print(f"RATIO cpgsim whole call Simulator(g).run(T)/C at {r['neurons']} neurons = "
                  f"{r['cpgsim_call_over_c']:.2f} (target <= {TARGET_CALL:g}: {met})")
        for r in report["ratios"]:
            if r["fastest_peer_over_cpgsim"] is None:
                print(f"RATIO fastest_peer/cpgsim at {r['neurons']} neurons = n/a (no peer ran)")
                continue
            met = "met" if r["fastest_peer_over_cpgsim"] >= TARGET_PEER else "not met"
            print(f"RATIO fastest_peer/cpgsim at {r['neurons']} neurons = {r['fastest_peer_over_cpgsim']:.1f} "
                  f"({r['fastest_peer']}; target >= {TARGET_PEER:g}: {met})")
    if args.json:
        args.json.write_text(json.dumps(report, indent=2))
        print(f"wrote {args.json}")


if __name__ == "__main__":
    main()
