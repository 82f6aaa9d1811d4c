"""A run freezes the objects that exist at its start (harness.gc_freeze) and gives them back; someone else's
freeze and a disabled collector are left alone; garbage the run makes is still collected."""

from __future__ import annotations

import gc
import weakref

import numpy as np

from cpgsim.components.basic import Integrator
from cpgsim.components.core import CoSimBlock
from cpgsim.harness.gc_freeze import frozen_heap
from cpgsim.harness.simulate import Simulator


class _Node:
    """A weak-referenceable object that can point at itself."""

    def __init__(self) -> None:
        self.me = self


class _Probe(CoSimBlock):
    """A co-simulation block that notes the collector's freeze count at each step and makes a reference cycle."""

    def __init__(self, name: str = "probe") -> None:
        self.seen: list[int] = []
        self.cycles: list[weakref.ref] = []
        super().__init__(name)

    def declare(self) -> None:
        self.add_output("y", 1)

    def setup(self, t0: float) -> None:
        self.seen.clear()

    def do_step(self, t: float, dt: float) -> None:
        self.seen.append(gc.get_freeze_count())
        self.cycles.append(weakref.ref(_Node()))  # a cycle only the collector can free

    def get_outputs(self) -> dict[str, np.ndarray]:
        return {"y": np.zeros(1)}

    def set_inputs(self, values) -> None:
        pass


def test_a_run_freezes_the_set_up_and_unfreezes_after():
    probe = _Probe()
    before = gc.get_freeze_count()
    assert before == 0
    Simulator(probe, dt=0.01).run(0.05)
    assert probe.seen and min(probe.seen) > 0  # frozen during the steps
    assert gc.get_freeze_count() == 0  # and given back
    gc.collect()
    assert all(r() is None for r in probe.cycles)  # the run's own cyclic garbage is collected


def test_someone_elses_freeze_and_a_disabled_collector_are_left_alone():
    gc.freeze()
    try:
        mine = gc.get_freeze_count()
        with frozen_heap() as froze:
            assert not froze and gc.get_freeze_count() == mine
        assert gc.get_freeze_count() == mine
    finally:
        gc.unfreeze()
    gc.disable()
    try:
        with frozen_heap() as froze:
            assert not froze and gc.get_freeze_count() == 0
        assert not gc.isenabled()
    finally:
        gc.enable()


def test_an_error_in_the_run_still_unfreezes():
    try:
        with frozen_heap():
            raise KeyError("boom")
    except KeyError:
        pass
    assert gc.get_freeze_count() == 0


def test_results_do_not_change():
    g = Integrator("i")
    a = Simulator(g, dt=0.01).run(1.0, inputs={"u": 1.0})
    gc.disable()
    try:
        b = Simulator(g, dt=0.01).run(1.0, inputs={"u": 1.0})
    finally:
        gc.enable()
    assert np.array_equal(a.data, b.data)
