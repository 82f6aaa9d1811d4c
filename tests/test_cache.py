"""The compiled-model cache: hits give the same model, misses follow every structural change.

Each test uses its own cache folder (``CPGSIM_CACHE``), so it starts cold.
"""

from __future__ import annotations

import numpy as np
import pytest

from cpgsim.components.basic import Sum
from cpgsim.components.library import hexapod_network
from cpgsim.harness.compile import compile_graph
from cpgsim.harness.simulate import Simulator


@pytest.fixture(autouse=True)
def private_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("CPGSIM_CACHE", str(tmp_path / "cache"))
    return tmp_path / "cache"


def entries(folder) -> list:
    return sorted((folder / "models").glob("*.json"))


def test_second_compile_is_a_hit_with_identical_results(private_cache):
    first = compile_graph(hexapod_network())
    second = compile_graph(hexapod_network())
    assert not first.from_cache and second.from_cache
    assert (first.compile_cache, second.compile_cache, compile_graph(hexapod_network(), cache=False).compile_cache) == (
        "miss", "hit", "off")
    assert len(entries(private_cache)) == 1
    a = Simulator(hexapod_network(), backend="casadi").run(1.0)
    b = Simulator(hexapod_network(), backend="casadi").run(1.0)
    assert np.array_equal(a.data, b.data)
    assert second.states.names() == first.states.names() and np.array_equal(second.p0, first.p0)


def test_parameter_values_are_data_not_part_of_the_key(private_cache):
    compile_graph(hexapod_network())
    g = hexapod_network()
    g.set_param("*.z1.omega", 1.0)
    hit = compile_graph(g)
    assert hit.from_cache and np.isclose(hit.p0[hit.params.index("leg1.z1.omega").start], 1.0)
    cached = Simulator(g, backend="casadi").run(2.0)
    default = Simulator(hexapod_network(), backend="casadi").run(2.0)
    assert not np.allclose(cached["leg1.z1.x"], default["leg1.z1.x"])
    g2 = hexapod_network()
    g2.set_param("*.z1.omega", 1.0)
    fresh = Simulator(g2, backend="casadi", cache=False)
    assert not fresh.model.from_cache
    run = fresh.run(2.0)
    assert np.array_equal(run.data, cached.data)
    assert run.meta["execution"]["compile_cache"] == "off" and cached.meta["execution"]["compile_cache"] == "hit"


def test_structural_changes_miss(private_cache):
    def graph(signs=(1, 1), wire="x1"):
        g = hexapod_network()
        g.add(Sum("s", signs=signs))
        g.connect(f"leg1.{wire}", "s.u1")
        g.connect("leg2.x1", "s.u2")
        return g

    base = compile_graph(graph())
    assert not base.from_cache
    assert compile_graph(graph()).from_cache
    assert not compile_graph(graph(signs=(1, -1))).from_cache  # a block's configuration
    assert not compile_graph(graph(wire="x2")).from_cache  # the wiring
    assert not compile_graph(graph(), dt=2e-3).from_cache  # the step
    assert len(entries(private_cache)) == 4


def test_damaged_entry_is_recompiled(private_cache):
    compile_graph(hexapod_network())
    (entry,) = entries(private_cache)
    entry.write_text(entry.read_text()[:100])
    again = compile_graph(hexapod_network())
    assert not again.from_cache
    assert compile_graph(hexapod_network()).from_cache


def test_cache_can_be_turned_off(private_cache, monkeypatch):
    compile_graph(hexapod_network(), cache=False)
    assert not compile_graph(hexapod_network(), cache=False).from_cache
    assert not (private_cache / "models").exists()
    from cpgsim.components import memo

    monkeypatch.setattr(memo, "_CACHING", [True])
    memo.set_caching(False)  # cpgsim --no-cache: the whole process
    assert not compile_graph(hexapod_network()).from_cache
    assert not (private_cache / "models").exists()


def test_grouped_model_from_cache_runs_natively(private_cache):
    from cpgsim.components.library import network_array

    cold = Simulator(network_array(12), backend="native")
    warm = Simulator(network_array(12), backend="native")
    assert cold.model.grouping == warm.model.grouping == "kinds" and warm.model.from_cache
    assert np.array_equal(cold.run(1.0).data, warm.run(1.0).data)


def test_locked_orbit_memo_matches_the_computation(private_cache, monkeypatch):
    from cpgsim.components.yu import converter

    converter._locked_orbit_disk.cache_clear()
    memo = converter.locked_orbit(0.1, 4.0, converter.TABLE1_OMEGA, 0.1)
    assert list((private_cache / "memo").glob("*.json"))
    converter._locked_orbit_disk.cache_clear()
    from cpgsim.components import memo as memo_module

    monkeypatch.setattr(memo_module, "_CACHING", [False])
    computed = converter.locked_orbit(0.1, 4.0, converter.TABLE1_OMEGA, 0.1)
    converter._locked_orbit_disk.cache_clear()
    assert memo == computed
    assert abs(computed.half_period - 2.5) < 0.1  # half the leader's period 2 pi / (0.4 pi) = 5 s


def _description(model) -> dict:
    """Every attribute of a compiled model but its functions and where it came from, as comparable text."""
    import dataclasses

    skip = {"ode", "signals", "discrete", "step", "compile_cache", "flat", "_c_source", "_schedule", "_wiring"}
    return {f.name: repr(getattr(model, f.name)) for f in dataclasses.fields(model) if f.name not in skip}


def _schedule_shape(s) -> list:
    """A schedule as plain data: per signal level, each group's kind, its function's name and size, and its
    index tables (where each instance reads and writes)."""
    def group(g) -> tuple:
        tables = [np.asarray(a).tolist() for a in (g.x_off, g.z_off, g.p_off, g.u_idx, *g.out_off)]
        return g.kind.label, g.fn.name(), g.fn.n_instructions(), tables, list(g.out_target)
    return [[group(g) for g in level] for level in s.signal_levels]


@pytest.mark.parametrize("grouping", ["flat", "kinds"])
def test_a_cached_model_is_the_same_object_as_a_fresh_one(private_cache, grouping):
    """Issue 59: a model loaded from the cache had schedule None where a fresh one had its schedule. Now
    it has the same attributes and the same schedule (built from its wiring on first use), so the grouped C
    step it would generate is the same text."""
    from cpgsim.harness.compiler.c_form import c_step_source

    fresh = compile_graph(hexapod_network(), grouping=grouping, cache=False)
    compile_graph(hexapod_network(), grouping=grouping)
    cached = compile_graph(hexapod_network(), grouping=grouping)
    assert cached.from_cache and not fresh.from_cache
    assert _description(cached) == _description(fresh)
    assert cached.schedule is not None
    assert _schedule_shape(cached.schedule) == _schedule_shape(fresh.schedule)
    assert [k.label for k in cached.schedule.kinds] == [k.label for k in fresh.schedule.kinds]
    if grouping == "kinds":
        assert c_step_source(cached.schedule, cached.dt, cached.substeps) == fresh.c_step_source()
