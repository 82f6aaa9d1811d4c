"""An isolated FMU without inputs or clocks runs ahead of the master on its time grid (``fmus/importer/isolation.py``,
``RUN_AHEAD``): one request asks the child for several macro steps at ``t0 + k dt`` and the child sends each
step's outputs as it is done, so the parent reads them instead of waiting for a round trip per step.

What must not change, and is checked here: the recorded rows are those of the same FMU in process, bit for
bit; a stop request, an error, a crash or a hang at a step is reported at that step, with the same message as
without running ahead, and the child steps no further after a stop or an error; a step off the grid after the
child ran ahead is refused (it cannot go back); a run that ends before the steps computed ahead are taken
ends cleanly. The number of requests is counted (far fewer than the steps), not timed.
"""

from __future__ import annotations

import numpy as np
import pytest
import test_fmu_hybrid as hybrid
import test_isolation_protocol as protocol
from test_isolation_protocol import StandIn, assert_gone, runtime, serve

from cpgsim.fmus.errors import FmuCrashedError, FmuRuntimeError, FmuTimeoutError
from cpgsim.fmus.importer import isolation
from cpgsim.fmus.importer.block import FmuBlock
from cpgsim.fmus.importer.isolation import IsolatedRuntime
from cpgsim.harness.errors import StopRequested
from cpgsim.harness.simulate import simulate

fmus = protocol.fmus  # the C FMUs, well-behaved and hostile (module fixture)
stop_fmus = hybrid.stop_fmus  # FMUs that ask to stop at t = 9 s
c_fmus = hybrid.c_fmus  # the bouncing ball (ME, events)


@pytest.fixture
def counted(monkeypatch):
    """The (requests sent, grid steps taken) of every isolated runtime, noted when it is terminated."""
    seen: list[tuple[int, int, int]] = []
    real = IsolatedRuntime.terminate

    def terminate(self):
        seen.append((self.requests, self._k, self.run_ahead))
        real(self)

    monkeypatch.setattr(IsolatedRuntime, "terminate", terminate)
    return seen


def test_the_child_runs_ahead_and_stops_at_a_stop_request(monkeypatch):
    args = {"path": "/x.fmu", "kind": "cs", "instance_name": "b"}
    replies = serve(monkeypatch, [
        ("ready", ()),
        ("setup", (args, 0.0, {}, {})),
        ("ahead", (0.0, 0.5, 0, 4)),  # t = 0, 0.5, 1 (StandIn asks to stop at t >= 1), 1.5
        ("ahead", (0.0, 0.5, 4, 2)),  # asked before the parent saw the stop: skipped
        ("outputs", ({},)),
        ("terminate", ()),
    ])
    rt = StandIn.made[0]
    assert replies[2][0] == "ok" and replies[2][1]["y"].tolist() == [0.5]
    assert replies[1][1][isolation._TICKS] == {"tick": [0.5]} and isolation._TICKS not in replies[2][1]
    assert replies[3][0] == "ok" and replies[3][1]["y"].tolist() == [1.0]
    assert replies[4] == ("stop", ("the model reached its end", 1.0))
    assert replies[5:8] == [("skip", None)] * 3, "the child stepped on after a stop request"
    assert replies[8][0] == "ok" and replies[8][1]["y"].tolist() == [1.0]
    assert replies[9] == ("ok", None)
    assert [e for e in rt.log if e[0] == "do_step"] == [("do_step", 0.0, 0.5), ("do_step", 0.5, 0.5),
                                                      ("do_step", 1.0, 0.5)]


def test_packed_values_keep_their_bits_dtypes_and_shapes():
    values = {"a": np.array([0.1, -0.0, np.nan, np.inf]), "b": np.array([2**62 + 1, -5], dtype=np.int64),
              "c": np.array([2**64 - 1], dtype=np.uint64), "d": np.zeros((2, 3)), "e": np.zeros(0)}
    layout, data = isolation._pack_inputs(values)
    back = isolation._unpack(isolation._fields(layout), data)
    assert list(back) == list(values)
    for k, v in values.items():
        assert back[k].dtype == v.dtype and back[k].shape == v.shape and back[k].tobytes() == v.tobytes()
        assert back[k].flags.writeable
    other = {"s": np.array(["x"], dtype=object)}
    assert isolation._pack_inputs(other) == other, "values that are not numeric arrays are sent as they are"


@pytest.mark.parametrize("hostile, error, message", [
    ("SEGV", FmuCrashedError, "crashed (signal SIGSEGV) during step at t=0.05 s"),
    ("SLEEP", FmuTimeoutError, "step at t=0.05 s took longer than 1 s (--fmu-timeout)"),
])
@pytest.mark.slow
def test_a_crash_or_hang_while_running_ahead_is_reported_at_its_step(fmus, tmp_path, hostile, error, message):
    """The hostile C FMUs turn hostile at the doStep from t = 0.05 s; stepped at 0.01 s without inputs, the
    child computes the steps from 0 to 0.04 and their outputs are taken, then the step at 0.05 fails as it
    does one round trip at a time."""
    for ahead in (0, 8):
        rt = IsolatedRuntime(runtime(fmus[hostile], tmp_path).args, timeout=1.0, run_ahead=ahead)
        rt.setup(0.0)
        for k in range(5):
            rt.do_step(0.01 * k, 0.01)
            assert rt.get_outputs()["y"].tolist() == [0.0]
        with pytest.raises(error) as err:
            rt.do_step(0.01 * 5, 0.01)
        assert message in str(err.value), (ahead, str(err.value))
        # ready, setup, then a step each, or steps 0-7 asked for at the first and 8-15 at the fifth (half taken)
        assert rt.requests == (2 + 6 if ahead == 0 else 2 + 2)
        rt.terminate()
        assert_gone(rt)


@pytest.mark.slow
def test_a_step_off_the_grid_is_refused_and_an_early_end_is_clean(fmus, tmp_path):
    rt = IsolatedRuntime(runtime(fmus["good"], tmp_path).args, run_ahead=8)
    try:
        rt.setup(0.0)
        rt.do_step(0.0, 0.25)
        rt.do_step(0.25, 0.25)
        with pytest.raises(FmuRuntimeError, match="not the next step on the grid"):
            rt.do_step(0.75, 0.25)
        assert rt._asked - rt._k == 6  # computed ahead, never taken: read and dropped at the end
        rt.set_inputs({"u": np.array([1.0])})  # inputs for a step the FMU has already taken
        with pytest.raises(FmuRuntimeError, match="cannot go back"):
            rt.get_outputs()
    finally:
        rt.terminate()
    assert rt.proc.returncode == 0
    assert_gone(rt)


@pytest.mark.slow
def test_inputs_or_an_irregular_first_step_mean_one_round_trip_per_step(fmus, tmp_path):
    rt = IsolatedRuntime(runtime(fmus["good"], tmp_path).args, run_ahead=8)
    try:
        rt.setup(0.0)
        rt.do_step(0.1, 0.25)  # not at t0: no grid, as without running ahead
        assert rt.run_ahead == 0 and rt._asked == 0
        rt.set_inputs({"u": np.array([1.0])})
        rt.do_step(0.35, 0.25)
        assert rt.get_outputs()["y"].tolist() == [0.25]
    finally:
        rt.terminate()
    assert_gone(rt)


def same_rows(block_args: dict, counted: list, **run) -> tuple[np.ndarray, int, int]:
    out = {}
    for iso in (False, True):
        out[iso] = simulate(FmuBlock(isolate=iso, **block_args), **run)
    assert np.array_equal(out[False].data, out[True].data, equal_nan=True), "isolated rows differ from in process"
    assert out[False].time.tolist() == out[True].time.tolist()
    assert out[False].meta.get("stopped_by") == out[True].meta.get("stopped_by")
    requests, steps, _ = counted[-1]
    return out[True].data, requests, steps


@pytest.mark.slow
@pytest.mark.parametrize("fmi, kind", [(2, "cs"), (3, "cs"), (2, "me")])
def test_a_stop_request_while_running_ahead_gives_the_rows_of_the_run_in_process(stop_fmus, counted, fmu_tmp,
                                                                                  fmi, kind):
    data, requests, steps = same_rows(dict(name="stop", path=stop_fmus[fmi], kind=kind), counted, t_end=20.0,
                                      dt=0.1)
    assert len(data) == 91
    # ready, setup, steps asked for ahead at steps 0, 16, 48 and 80, maybe the outputs after the stop (not 93)
    assert requests <= 7 if isolation.RUN_AHEAD == 32 else requests < 20


@pytest.mark.slow
def test_an_me_fmu_with_events_gives_the_rows_of_the_run_in_process(c_fmus, counted, fmu_tmp):
    _, requests, steps = same_rows(dict(name="ball", path=c_fmus["ball"], solver="cvode", rtol=1e-10, atol=1e-10),
                                   counted, t_end=hybrid.T_END, dt=0.01)
    assert counted[-1][2] == isolation.RUN_AHEAD  # still running ahead at the end
    assert requests <= 3 + 370 // (isolation.RUN_AHEAD // 2), requests  # ready, setup, ahead..., not one per step


@pytest.mark.slow
def test_an_fmu_with_inputs_does_not_run_ahead(fmus, counted, fmu_tmp):
    blk = FmuBlock("plant", fmus["good"], isolate=True)
    assert blk.info.inputs
    simulate(blk, t_end=0.1, dt=0.01)
    assert counted[-1][2] == 0


@pytest.mark.slow
def test_a_stop_seen_by_the_parent_drains_the_skipped_steps(fmus, tmp_path, monkeypatch):
    """After a stop request read from the steps run ahead, outputs are asked for again: the skipped replies
    the child still owes are read first, so the answer is the outputs', not a stale step's."""
    rt = IsolatedRuntime(runtime(fmus["good"], tmp_path).args, run_ahead=4)
    rt.setup(0.0)
    real = rt._reply
    calls = []

    def reply(what, timeout):
        calls.append(what)
        if what == "step" and len(calls) == 2:  # the second step: as if the FMU had asked to stop there
            real(what, timeout)
            rt._outputs = None
            raise StopRequested("stop here", 0.5)
        return real(what, timeout)

    monkeypatch.setattr(rt, "_reply", reply)
    rt.do_step(0.0, 0.25)
    with pytest.raises(StopRequested):
        rt.do_step(0.25, 0.25)
    assert rt._halted and rt.run_ahead == 0
    assert rt.get_outputs()["y"].tolist() == [0.0]
    assert calls == ["step", "step", "step", "step", "outputs"]  # two owed replies drained, then the answer
    rt.terminate()
    assert_gone(rt)
