"""cpgsim: typed blocks, signal-flow graphs and co-simulation for bio-inspired legged-robot controllers.

The public face of the package. The names below are loaded on first use (``cpgsim --help`` and
``import cpgsim`` stay fast: CasADi, DART and fmpy are imported only by what needs them)::

    import cpgsim
    g = cpgsim.leader_follower_network()           # Yu 2019 Y5 network, a Graph of blocks
    res = cpgsim.simulate(g, t_end=20.0, dt=1e-3)  # one compiled step, looped in C
    run = cpgsim.Results.load("runs/demo/results.arrow")  # a finished run, with units and metadata
    study = cpgsim.simulate_batch(g, params={"z1.eps": [0.05, 0.1]}, t_end=20.0)

Subpackages, lowest layer first: :mod:`cpgsim.components` (the block kit and each paper's blocks),
:mod:`cpgsim.harness` (the engine), then beside each other :mod:`cpgsim.fmus` (FMU export and import,
SSP), :mod:`cpgsim.robots` (the hexapod plant, its engines DART and MuJoCo, terrains) and
:mod:`cpgsim.verify` (limit cycles, proofs); above them :mod:`cpgsim.experiments` (the papers' scenarios)
and :mod:`cpgsim.cli` (the ``cpgsim`` command).
"""

from importlib import import_module as _import_module

__version__ = "0.3.0"

# public name -> module that defines it (relative to this package)
_EXPORTS: dict[str, str] = {
    # graphs and the block kit
    "Graph": "components.graph",
    "Block": "components.core",
    "CoSimBlock": "components.core",
    "Equations": "components.core",
    "Port": "components.core",
    "Parameter": "components.core",
    "State": "components.core",
    "ModelError": "components.core",
    # running, verifying, exchanging
    "simulate": "harness.simulate",
    "Simulator": "harness.simulate",
    "simulate_batch": "harness.batch",
    "verify": "verify.shooting",
    "VerifyOptions": "verify.result",
    "export_fmu": "fmus.export.exporter",
    "FmuBlock": "fmus.importer.block",
    "Results": "harness.results",
    # the block library: generic blocks
    "Constant": "components.basic",
    "StepSource": "components.basic",
    "SineSource": "components.basic",
    "Gain": "components.basic",
    "Sum": "components.basic",
    "Product": "components.basic",
    "Mux": "components.basic",
    "Demux": "components.basic",
    "Integrator": "components.basic",
    "UnitConversion": "components.basic",
    # Yu 2019: neurons, networks, sensory neurons, reflexes, converter, gait FSM, controllers
    "VanDerPolNeuron": "components.neurons",
    "LeaderDrive": "components.networks",
    "FollowerCoupling": "components.networks",
    "leader_follower_network": "components.networks",
    "SettableVanDerPolNeuron": "components.yu.reflexes",
    "YuReflexLogic": "components.yu.reflexes",
    "YuSensoryNeurons": "components.yu.sensors",
    "YuConverter": "components.yu.converter",
    "YuGaitFSM": "components.yu.fsm",
    "LegFK": "components.yu.leg",
    "hexapod_controller": "components.yu.leg",
    # Fukuhara 2022: load-sensing limb modes, foot trajectory, held leg, controller
    "LimbModeController": "components.fukuhara.blocks",
    "FootTrajectory": "components.fukuhara.blocks",
    "HeldLeg": "components.fukuhara.blocks",
    "fukuhara_controller": "components.fukuhara.controller",
}

__all__ = ["__version__", *_EXPORTS]


def __getattr__(name: str) -> object:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'cpgsim' has no attribute {name!r}")
    value = getattr(_import_module(f"{__name__}.{module}"), name)
    globals()[name] = value  # later look-ups skip this function
    return value


def __dir__() -> list[str]:
    """The public API only (what ``__all__`` lists), not this module's own helpers."""
    return sorted(__all__)
