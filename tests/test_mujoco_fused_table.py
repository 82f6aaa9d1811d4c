"""The MuJoCo fused loop writes each row straight into the recorder's table (FusedLoop.bind_table) and reports
whether every value it wrote was finite: the recorded numbers are those of the chunk-buffer path, the settle in
one C call leaves the plant where the step-by-step settle does, and a non-finite value the C loop wrote is still
found and named by the recorder's check."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("mujoco", reason="the mujoco package is not installed (pip install 'cpgsim[mujoco]')")

from cpgsim.experiments.runner import build_scenario  # noqa: E402
from cpgsim.harness.cosim.contracts import FusedStatus  # noqa: E402
from cpgsim.harness.cosim.fused import output_columns, run_fused  # noqa: E402
from cpgsim.harness.errors import SimulationDiverged  # noqa: E402
from cpgsim.harness.simulate import Simulator, _Recorder  # noqa: E402
from cpgsim.robots.mujoco.native import FusedLoop  # noqa: E402
from cpgsim.robots.mujoco.plant import MujocoHexapod  # noqa: E402
from cpgsim.robots.plant_base import HexapodPlant  # noqa: E402

MJ = {"robot.engine": "mujoco"}


def _run(t_end: float = 0.7):
    setup = build_scenario("step", MJ)
    sim = Simulator(setup.graph, dt=1e-3, record=setup.record, step_thread=False).prepare()
    res = sim.run(t_end, progress=False)
    return res, res.meta["execution"]


def test_rows_in_the_table_equal_the_chunk_buffer_path(monkeypatch):
    direct, ex = _run()
    assert ex["fused_loop"] is True
    monkeypatch.setattr(FusedLoop, "bind_table", lambda self, *a: False)  # the rows through Y/O, copied in Python
    buffered, _ = _run()
    assert direct.data.shape == buffered.data.shape == (701, len(direct.columns))
    assert np.array_equal(direct.data, buffered.data)
    assert direct.data.tobytes() == buffered.data.tobytes()  # -0.0 and +0.0 apart too


def test_the_settle_in_one_c_call_ends_where_the_step_by_step_settle_ends(monkeypatch):
    def settled():
        setup = build_scenario("step", MJ)
        plant = setup.graph.blocks[setup.robot]
        plant.setup(0.0)
        d = plant.data
        return (d.qpos.copy(), d.qvel.copy(), d.qacc_warmstart.copy(), plant._readout_out.copy(),
                plant._force_world.copy(), plant._link_contact.copy(), plant._body_contact)

    one_call = settled()
    monkeypatch.setattr(MujocoHexapod, "_settle", HexapodPlant._settle)  # one C call per MuJoCo step
    step_by_step = settled()
    for a, b in zip(one_call, step_by_step, strict=True):
        assert np.asarray(a).tobytes() == np.asarray(b).tobytes()


class _Runner:
    """A fused loop that writes its rows into the bound table itself, as the MuJoCo loop does."""

    output_slices = {"out": slice(0, 2)}
    chunk = 4

    def __init__(self, values: np.ndarray) -> None:
        self.values = values
        self.finite = False

    def bind_table(self, table, ycols, ocols, osrc) -> bool:
        self.table, self.ycols, self.ocols, self.osrc = table, ycols, ocols, osrc
        return True

    def run(self, k0, k1, times):
        rows = self.values[k0:k1]
        self.table[k0:k1, self.ycols] = rows[:, :1]
        self.table[k0:k1, self.ocols] = rows[:, 1:][:, self.osrc]
        self.finite = bool(np.isfinite(rows).all())
        return k1 - k0, FusedStatus.DONE, np.zeros((0, 1)), np.zeros((0, 2))


class _Plan:
    yj = np.array([0])
    c_slices = [("robot", "out", slice(1, 3))]
    c_fancy: list = []


class _Bar:
    def update(self, n) -> None:
        pass


def test_a_nan_written_by_the_loop_is_found_and_named():
    values = np.arange(30.0).reshape(10, 3)
    values[6, 2] = np.nan
    times = np.arange(11) * 1e-3
    rec = _Recorder(times, ["y", "robot.out[0]", "robot.out[1]"], ["", "", ""], prefault_rows=False)
    assert [list(a) for a in output_columns(_Plan, _Runner.output_slices)] == [[1, 2], [0, 1]]
    with pytest.raises(SimulationDiverged, match=r"robot\.out\[1\] became nan at t=0\.006"):
        run_fused(_Runner(values), _Plan, rec, times, 10, _Bar(), lambda: None)
    assert rec.n == 6  # the rows before the NaN are kept


def test_finite_chunks_are_not_checked_again():
    values = np.arange(30.0).reshape(10, 3)
    times = np.arange(11) * 1e-3
    rec = _Recorder(times, ["y", "robot.out[0]", "robot.out[1]"], ["", "", ""], prefault_rows=False)
    assert run_fused(_Runner(values), _Plan, rec, times, 10, _Bar(), lambda: None) == 10
    assert rec.n == rec.checked == 10
    assert np.array_equal(rec.data[:10], values)
