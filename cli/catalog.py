"""Built-in graphs by name, and loading user graphs from ``path/to/module.py:function``.

Entries are ``"module:function"`` strings imported on demand, so the CLI starts fast and a
broken optional dependency only affects the graph that needs it.
"""

from __future__ import annotations

import importlib
import importlib.util
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

from cpgsim.components.core import Block, ModelError, did_you_mean
from cpgsim.components.graph import Graph

BUILTIN: dict[str, tuple[str, str]] = {
    # name: ("module:function", one-line description)
    "vdp": ("cpgsim.components.library:single_vdp", "one Van der Pol neuron, Yu Y2 (eps 0.1, b 4, omega 0.4pi)"),
    "network": ("cpgsim.components.networks:leader_follower_network", "Yu Y5 leader-follower network, Table 1"),
    "network-searching": ("cpgsim.components.library:searching_network", "Yu Y13 searching-mode network"),
    "hexapod-network": ("cpgsim.components.library:hexapod_network", "six Y5 networks (18 neurons), legs 1-6"),
    "damped-oscillator": ("cpgsim.components.library:damped_oscillator",
                          "damped linear oscillator from generic blocks (no limit cycle)"),
    "leg": ("cpgsim.components.yu.leg:leg", "Yu single-leg controller: network, sensory neurons, reflexes, converter "
            "(input toe_force)"),
    "hexapod-controller": ("cpgsim.components.yu.leg:hexapod_controller", "Yu six-leg controller + gait FSM "
                           "(in: toe_force[18] N; out: q_target[18] rad)"),
    "fukuhara-controller": ("cpgsim.components.fukuhara.controller:fukuhara_controller",
                            "Fukuhara 2022 six-leg controller, rules 1-4 + Appendix A (in: toe_force[18] N; "
                            "out: q_target[18] rad)"),
}


class GraphNotFound(ModelError):
    """A graph name or ``module.py:function`` reference cannot be resolved."""


def names() -> list[str]:
    return sorted(BUILTIN)


OLD_TOP_LEVEL = ("components", "harness", "fmus", "robots")


MOVED_APPLICATIONS = ("experiments", "verify", "cli")
"""Subpackages of ``harness`` before cpgsim 0.3, now top-level folders above the engine."""


def moved_name_hint(exc: BaseException, requested: str | None = None) -> str | None:
    """The one-line advice for code written against the names before cpgsim 0.2 (``components``, ``harness``,
    ``fmus``, ``robots`` were top-level packages; now they are ``cpgsim.components`` and so on) or before 0.3
    (``harness.experiments``, ``.verify`` and ``.cli``, with or without ``cpgsim.``, are now
    ``cpgsim.experiments`` and so on). ``requested``: the full module name asked for, when known (the exception
    names only its first missing part)."""
    name = getattr(exc, "name", None) if isinstance(exc, ModuleNotFoundError) else None
    if not name:
        return None
    if requested and requested.startswith(name):
        name = requested
    parts = name.split(".")
    in_package = parts[0] == "cpgsim"
    if in_package:
        parts = parts[1:]
    elif parts[0] not in OLD_TOP_LEVEL:
        return None
    moved_app = len(parts) > 1 and parts[0] == "harness" and parts[1] in MOVED_APPLICATIONS
    if in_package and not moved_app:
        return None  # a cpgsim name that never existed: no advice
    new = ".".join(["cpgsim", *(parts[1:] if moved_app else parts)])
    release = "0.3 moved the applications above the engine" if moved_app else "0.2 installs one package, cpgsim"
    return f"module {name!r} is now {new!r} (cpgsim {release}): write 'from {new} import ...'"


def _import_target(target: str) -> Callable[[], Any]:
    module, _, func = target.partition(":")
    mod = importlib.import_module(module)
    return getattr(mod, func)


def load_graph(spec: str) -> Graph | Block:
    """Resolve a built-in name, ``path/to/module.py:function`` or an ``.fmu``/``.ssp`` file to a graph (or block)."""
    if spec.lower().endswith((".fmu", ".ssp")):
        from cpgsim.fmus.loader import load_fmu_graph

        return load_fmu_graph(spec)
    if spec in BUILTIN:
        builder = _import_target(BUILTIN[spec][0])
    elif ":" in spec:
        path_str, _, func = spec.rpartition(":")
        path = Path(path_str)
        if not path.exists():
            raise GraphNotFound(f"graph file {path} does not exist")
        mod_name = f"cpgsim_user_{abs(hash(path.resolve()))}"
        spec_obj = importlib.util.spec_from_file_location(mod_name, path)
        if spec_obj is None or spec_obj.loader is None:
            raise GraphNotFound(f"cannot import {path} as a Python module")
        module = importlib.util.module_from_spec(spec_obj)
        sys.modules[mod_name] = module
        try:
            spec_obj.loader.exec_module(module)
        except SystemExit as exc:  # user code ending the process is bad input, not cpgsim's exit status
            raise GraphNotFound(f"importing {path} failed: the module called sys.exit({exc.code!r})") from None
        except Exception as exc:  # noqa: BLE001 - user code: report, don't crash
            hint = moved_name_hint(exc)
            if hint:
                raise GraphNotFound(f"importing {path} failed: {hint}") from None
            raise GraphNotFound(f"importing {path} failed: {type(exc).__name__}: {exc}") from exc
        if not hasattr(module, func):
            raise GraphNotFound(f"{path} has no function {func!r}")
        builder = getattr(module, func)
    else:
        raise GraphNotFound(f"unknown graph {spec!r}: use one of {', '.join(names())} or path/to/module.py:function"
                            f"{did_you_mean(spec, names())}")
    return call_builder(builder, spec)


def call_builder(builder: Any, spec: str) -> Graph | Block:
    """Call a graph builder without arguments; whatever goes wrong in user code is one-line :class:`GraphNotFound`
    (a :class:`~cpgsim.components.core.ModelError` the builder raises keeps its own message)."""
    if not callable(builder):
        raise GraphNotFound(f"{spec}: {type(builder).__name__} object is not callable (need a function returning "
                            f"a Graph or Block)")
    import inspect

    try:
        sig = inspect.signature(builder)
    except (TypeError, ValueError):
        sig = None
    if sig is not None:
        required = [n for n, q in sig.parameters.items() if q.default is inspect.Parameter.empty
                    and q.kind in (q.POSITIONAL_ONLY, q.POSITIONAL_OR_KEYWORD, q.KEYWORD_ONLY)]
        if required:
            raise GraphNotFound(f"{spec}: the builder needs argument(s) {', '.join(required)}; "
                                f"it must be callable without arguments")
    try:
        graph = builder()
    except ModelError:
        raise
    except SystemExit as exc:
        raise GraphNotFound(f"{spec}: the builder called sys.exit({exc.code!r})") from None
    except Exception as exc:  # noqa: BLE001 - user code: report, don't crash
        raise GraphNotFound(f"{spec}: the builder raised {type(exc).__name__}: {' '.join(str(exc).split())}") \
            from exc
    if not isinstance(graph, (Graph, Block)):
        raise GraphNotFound(f"{spec} returned {type(graph).__name__}, not a Graph or Block")
    return graph
