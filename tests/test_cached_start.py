"""The cache-hit path of ``Simulator(graph)`` (issue 46, item 4): what it was made cheaper with keeps every result.

A port's size is computed once; the compile reads each block's tables in one pass (the layouts, the start
values, the leaf signatures); slots are made when first read; wires between leaf ports of one graph are checked
for a unit conversion while flattening; the cache key writes each distinct signature once; a cached model makes
its feedthrough sets on first use. Each test pins what the faster path must still give: the same sizes, the same
signatures, the same slots, a key that changes with every input of the equations, the same model.
"""

from __future__ import annotations

import dataclasses
import math
import pickle

import numpy as np
import pytest

from cpgsim.components.basic import Gain
from cpgsim.components.core import Block, Equations, Parameter, Port, State
from cpgsim.components.graph import Graph
from cpgsim.components.library import hexapod_network, network_array
from cpgsim.components.networks import leader_follower_network
from cpgsim.components.neurons import VanDerPolNeuron
from cpgsim.harness.compile import compile_graph, model_key
from cpgsim.harness.compiler import kinds
from cpgsim.harness.compiler.layout import Layout
from cpgsim.harness.compiler.wiring import Wiring
from cpgsim.harness.simulate import simulate


@pytest.fixture(autouse=True)
def private_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("CPGSIM_CACHE", str(tmp_path / "cache"))


@pytest.mark.parametrize("shape", [1, 3, (2, 3), (1, 1, 4)])
@pytest.mark.parametrize("kind,default", [("real", None), ("real", 0.5), ("integer", 2), ("boolean", 0.0)])
@pytest.mark.parametrize("direction", ["in", "out"])
def test_the_cached_port_size_is_the_product_of_the_shape(shape, kind, default, direction):
    port = Port("p", direction, shape, "1", kind, default=default if direction == "in" else None)
    assert port.size == math.prod(port.shape)
    assert [f.name for f in dataclasses.fields(Port)].count("size") == 0  # not a field: eq, hash, repr as before
    twin = Port("p", direction, shape, "1", kind, default=default if direction == "in" else None)
    assert port == twin and hash(port) == hash(twin) and "size" not in repr(port)
    other = dataclasses.replace(port, shape=(5,))
    assert other.size == 5 and port.size == math.prod(port.shape)
    assert pickle.loads(pickle.dumps(port)).size == port.size
    assert Parameter("k", 1.0).size == 1 and State("x", (0.0, 1.0)).size == 2


def _flat_graphs():
    g = Graph("mixed")
    g.add(leader_follower_network("net"))
    g.add(Gain("k", k=2.0))
    g.connect("net.x1", "k.u")
    return {"hexnet": hexapod_network(), "array": network_array(3, expose_modes=True), "mixed": g}


@pytest.mark.parametrize("name", ["hexnet", "array", "mixed"])
def test_the_wiring_pass_gives_the_leaf_signatures(name):
    """The signatures the wiring makes in its pass over the blocks (what ``compile_graph`` keys the cache with)
    are :func:`kinds.leaf_signatures` (what the public ``model_key`` uses), equal ones one object."""
    flat = _flat_graphs()[name].flatten()
    w = Wiring(flat, 1e-3, 1, signer=kinds.Signatures(flat))
    alone = kinds.leaf_signatures(flat)
    assert Wiring(flat, 1e-3, 1).signatures is None  # without a signer: left to the kinds
    assert w.signatures == alone and list(w.signatures) == list(alone)
    for sigs in (w.signatures, alone):
        first: dict[tuple, tuple] = {}
        for sig in sigs.values():
            assert first.setdefault(sig, sig) is sig  # equal signatures are one object


def test_slots_made_on_first_read_are_those_add_makes():
    flat = hexapod_network().flatten()
    w = Wiring(flat, 1e-3, 1)
    for layout, table in ((w.states, "states"), (w.dstates, "discrete_states"), (w.params, "parameters"),
                          (w.sig, "outputs")):
        eager = Layout()
        for path, blk in w.eq_blocks.items():
            for d in getattr(blk, table).values():
                eager.add(f"{path}.{d.name}", d.size, d.unit, d.kind, d.description)
        assert layout.size == eager.size  # known before any slot is made
        assert layout.slots == eager.slots and layout.names() == eager.names()
        extra = layout.add("extra", 2)
        assert extra.start == eager.size and layout.size == eager.size + 2


def test_a_layout_is_what_the_blocks_declared_when_it_was_made():
    """The declarations are frozen objects kept as given: a block changed after the compile (a new start value
    replaces its State) does not change the model's layout or start values."""
    g = hexapod_network()
    model = compile_graph(g, cache=False)
    before = [(s.name, s.start, s.size) for s in model.states.slots]
    x0 = model.x0.copy()
    g2 = hexapod_network()
    m2 = compile_graph(g2, cache=False)
    g2.find("leg1.z1").set_start("x", 0.25)
    assert [(s.name, s.start, s.size) for s in m2.states.slots] == before
    assert np.array_equal(m2.x0, x0) and np.array_equal(model.x0, x0)


def _leaf(**kw):
    g = Graph("g")
    g.add(VanDerPolNeuron("z", **kw))
    return g


class _Scaled(Block):
    """A block whose equations read an attribute (``scale``) and fold an unconnected input's default."""

    def __init__(self, name, scale=2.0, default=0.0, **kw):
        self.scale = scale
        self._default = default
        super().__init__(name, **kw)

    def declare(self):
        self.add_parameter("k", 1.0)
        self.add_input("u", default=self._default)
        self.add_state("x", 0.0)
        self.add_output("y")

    def define(self, v):
        return Equations(derivatives={"x": -v.p["k"] * v.x["x"] + v.u["u"]}, outputs={"y": self.scale * v.x["x"]})


def _scaled(**kw):
    g = Graph("g")
    for i in range(3):
        g.add(_Scaled(f"b{i}", **kw))
    return g


def test_the_key_changes_with_every_input_of_the_equations():
    """A block attribute, an input's default (a folded constant), a declaration, the wiring: each changes the
    key; parameter values and defaults do not (they are data: the parameter vector)."""
    base = model_key(_scaled())
    assert model_key(_scaled()) == base
    assert model_key(_scaled(scale=3.0)) != base  # an attribute define reads
    assert model_key(_scaled(default=0.5)) != base  # an unconnected input's default
    assert model_key(_scaled(k=4.0)) == base  # a parameter value
    g = _scaled()
    g.find("b1").parameters["k"] = Parameter("k", 7.0)  # a parameter's declared default: data too
    assert model_key(g) == base
    g = _scaled()
    g.find("b2").scale = 3.0  # one block of three
    assert model_key(g) != base
    wired = _scaled()
    wired.connect("b0.y", "b1.u")
    assert model_key(wired) != base
    assert model_key(_leaf(eps=0.3)) == model_key(_leaf())


def test_equal_signatures_fold_to_the_same_functions():
    """The key writes each distinct signature once (by its first block): exact because blocks with equal
    signatures have the same equations. The only equal-but-differently-printed values a signature holds are
    input defaults 0.0/-0.0 (and 1/1.0 on integer inputs, both folded as floats): CasADi folds them alike."""
    neg, pos = _Scaled("a"), _Scaled("a")
    neg.inputs["u"] = dataclasses.replace(neg.inputs["u"], default=-0.0)
    assert kinds.leaf_signature(neg, ()) == kinds.leaf_signature(pos, ())
    assert repr(kinds.leaf_signature(neg, ())) != repr(kinds.leaf_signature(pos, ()))

    def function(blk):
        kind = kinds._leaf_kind(0, blk, (), "a")
        return kind.function("f", [kind.xdot, *kind.outputs.values()])

    assert function(neg).serialize() == function(pos).serialize()


@pytest.mark.parametrize("grouping", ["flat", "kinds"])
def test_a_cached_model_is_the_compiled_one(grouping):
    """Loaded from the cache (layouts made on first read, feedthrough sets made on first use), a model has what
    the compile that stored it had: layouts, start values, feedthrough, graph outputs, the same step."""
    fresh = compile_graph(network_array(4, expose_modes=True), grouping=grouping)
    cached = compile_graph(network_array(4, expose_modes=True), grouping=grouping)
    assert fresh.compile_cache == "miss" and cached.compile_cache == "hit"
    for name in ("states", "dstates", "inputs", "params", "signals_layout"):
        assert getattr(cached, name).slots == getattr(fresh, name).slots, name
    assert cached.feed == fresh.feed and all(isinstance(v, set) for d in cached.feed.values() for v in d.values())
    for name in ("x0", "z0", "p0"):
        assert np.array_equal(getattr(cached, name), getattr(fresh, name))
    assert cached.graph_outputs == fresh.graph_outputs and cached.cosim_feeds == fresh.cosim_feeds
    u = np.full(fresh.inputs.size, 0.7)
    for a, b in zip(fresh.step(0.0, fresh.x0, fresh.z0, u, fresh.p0),
                    cached.step(0.0, cached.x0, cached.z0, u, cached.p0), strict=True):
        assert np.array_equal(np.asarray(a), np.asarray(b))
    assert model_key(network_array(4, expose_modes=True), grouping=grouping) == model_key(
        network_array(4, expose_modes=True), grouping=grouping)


def test_wires_checked_while_flattening_still_get_their_conversions():
    """Wires between two leaf blocks of one graph are checked for a unit conversion while flattening; a wire of
    two units of one dimension still gets its conversion block, one of equal units none."""
    class Mm(Block):
        def declare(self):
            self.add_output("q", unit="mm")

        def define(self, v):
            return Equations(outputs={"q": 1.0})

    class M(Block):
        def declare(self):
            self.add_input("q", unit="m")
            self.add_input("r", unit="mm", default=0.0)
            self.add_output("y", unit="m")

        def define(self, v):
            return Equations(outputs={"y": v.u["q"] + v.u["r"]})

    g = Graph("g")
    g.add(Mm("a"))
    g.add(M("b"))
    g.connect("a.q", "b.q")
    g.connect("a.q", "b.r")
    flat = g.flatten()
    assert set(flat.conversions) == {"b.q"} and flat.sources["b.q"] == "b__q_unit.y"
    assert flat.sources["b.r"] == "a.q" and flat.plain_wires == {"b.r": "a.q"}
    assert np.allclose(simulate(g, 0.002, cache=False)["b.y"], 1e-3 + 1.0)  # 1 mm as m, plus 1 mm as is
