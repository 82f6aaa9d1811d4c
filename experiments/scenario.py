"""Robot scenarios as data: a TOML document validated against one schema, with ``KEY=VALUE`` overrides.

A scenario file (the built-ins are ``experiments/scenarios/*.toml``)::

    name = "step"
    description = "Yu 2019, Sec. 6.1.1: a 40 mm step under the right legs"
    t_end = 30.0                      # s simulated
    seed = 0                          # random parts (initial alpha, random blocks, position jitter)

    [robot]                           # a geometry preset plus overrides, and the plant's servo gains
    preset = "yu-sim"                 # yu-sim (Yu Table 3) | yu-prototype (Yu Table 4)
    engine = "dart"                   # dart (default) | mujoco (docs/engines.md)
    stance_width = 0.075              # m; also body_mass, height, clearance, ...; kp, kd, friction

    [controller]
    kind = "yu"                       # yu | yu-open-loop (reflexes off) | fukuhara
    Fcx = 10.0                        # Yu: sensory thresholds (N), clearance_elevator (m), gait
    [controller.params]               # any parameter of the controller graph, by path (globs allowed)
    "*.converter.height_memory" = 1.0

    [terrain]                         # named features (cpgsim.robots.terrain.FEATURES), in file order
    friction = 1.0
    jitter_m = 0.0                    # shift every feature by U(-j, j) in y, from the seed
    [terrain.step]
    type = "step"
    height = 0.04
    position_y = 0.41
    side = "right"

    [criteria]                        # what "success" means (cpgsim.experiments.outcomes)
    max_tilt_deg = 30.0
    min_distance_m = 0.3

    [[disturbance]]                   # pushes on the body (cpgsim.robots.disturbance), any number
    start_s = 6.0
    duration_s = 0.2
    force_N = [0.0, -20.0, 0.0]       # world frame: +y is the walking direction
    point_m = [0.0, 0.0, 0.0]         # body frame (optional): where on the body

Overrides (``cpgsim run NAME --set KEY=VALUE``, ``cpgsim sweep --set/--vary``): ``KEY`` is a dotted path
into the document (``terrain.step.height``, ``robot.body_mass``, ``controller.Fcx``, ``t_end``); a path
under ``controller.`` that is not a key of the schema is a controller graph parameter
(``controller.R1.reflex.x1_apex`` -> ``[controller.params]``); a key without a dot is looked up in the
file's ``[aliases]`` table and then under ``controller.`` (``rule2=0`` is ``controller.rule2``). ``VALUE``
is a TOML value (``0.06``, ``true``, ``[1, 2]``, ``"left"``); a bare word is a string (``left``).
Setting ``terrain.NAME.type`` adds a feature. Every unknown key, wrong type or out-of-range value is a
:class:`ScenarioError` naming the key (and the file and line where it was written).
"""

from __future__ import annotations

import math
import re
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

from cpgsim.components.core import ModelError, did_you_mean

BUILTIN_PACKAGE = "cpgsim.experiments.scenarios"
CONTROLLER_KINDS = ("yu", "yu-open-loop", "fukuhara")
ROBOT_PRESETS = ("yu-sim", "yu-prototype")
ROBOT_ENGINES = ("dart", "mujoco")  # cpgsim.robots.registry.ENGINES (this layer does not import robots)


class ScenarioError(ModelError):
    """A scenario file or override is invalid (the message names the key, file and line)."""


@dataclass(frozen=True)
class Field:
    """One key of the schema: its type, default (``None``: optional without default), bounds, choices."""

    kind: type
    default: Any = None
    lo: float | None = None
    hi: float | None = None
    strict: bool = False  # lo is exclusive
    choices: tuple | None = None
    doc: str = ""

    def check(self, key: str, value: Any, where: str) -> Any:
        if self.kind is float:
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise ScenarioError(f"{key} must be a number, got {_show(value)}{where}")
            value = float(value)
            if not math.isfinite(value):
                raise ScenarioError(f"{key} must be finite, got {value}{where}")
        elif self.kind is int:
            if isinstance(value, float) and value.is_integer():
                value = int(value)
            if isinstance(value, bool) or not isinstance(value, int):
                raise ScenarioError(f"{key} must be an integer, got {_show(value)}{where}")
        elif self.kind is bool:
            if not isinstance(value, bool):
                raise ScenarioError(f"{key} must be true or false, got {_show(value)}{where}")
        elif self.kind is str:
            if not isinstance(value, str):
                raise ScenarioError(f"{key} must be a string, got {_show(value)}{where}")
        elif self.kind is list:
            if not isinstance(value, list):
                raise ScenarioError(f"{key} must be a list, got {_show(value)}{where}")
        if self.choices is not None and value not in self.choices:
            raise ScenarioError(f"{key} must be one of {', '.join(map(str, self.choices))}, got {_show(value)}{where}")
        if self.lo is not None and (value <= self.lo if self.strict else value < self.lo):
            raise ScenarioError(f"{key} = {value} is out of range: must be {'>' if self.strict else '>='} "
                                f"{self.lo:g}{where}")
        if self.hi is not None and value > self.hi:
            raise ScenarioError(f"{key} = {value} is out of range: must be <= {self.hi:g}{where}")
        return value


POSITIVE = {"lo": 0.0, "strict": True}
GEOMETRY_KEYS = ("body_length", "body_width", "body_thickness", "body_mass", "height", "clearance", "stance_width")

MUJOCO_SCHEMA: dict[str, Field] = {  # the fields of cpgsim.robots.mujoco.mjcf.ContactModel, which checks the values
    "timestep": Field(float, **POSITIVE, doc="s, MuJoCo's step (the 1 ms control step a multiple of it)"),
    "solref": Field(list, doc="[time constant s, damping ratio] of every contact's spring-damper"),
    "solimp": Field(list, doc="[d0, dwidth, width m]: contact impedance"),
    "condim": Field(int, choices=(1, 3, 4, 6), doc="contact dimensions (3: Coulomb friction)"),
    "cone": Field(str, choices=("pyramidal", "elliptic"), doc="friction cone"),
    "impratio": Field(float, **POSITIVE, doc="frictional over normal constraint impedance"),
    "noslip_iterations": Field(int, lo=0, doc="MuJoCo's noslip post-solver (0: off)"),
}
"""``[robot.mujoco]``: MuJoCo's contact model for a ``robot.engine = "mujoco"`` run (docs/engines.md)."""

DART_SCHEMA: dict[str, Field] = {  # the DART plant's own constructor options (cpgsim.robots.dart.plant.DartHexapod)
    "time_step": Field(float, **POSITIVE, doc="s, DART's world step (the 1 ms control step a multiple of it; "
                                              "below 1 ms the plant steps in Python)"),
    "detector": Field(str, choices=("dart", "fcl", "bullet", "ode"), doc="DART's collision detector"),
}
"""``[robot.dart]``: DART's numerics for a ``robot.engine = "dart"`` run (docs/engines.md, the convergence study)."""

ANKLE_SCHEMA: dict[str, Field] = {  # cpgsim.robots.description.AnkleSpring, which checks the values
    "stiffness": Field(float, **POSITIVE, doc="N/m, the ankle spring along the tibia (Yu 2019, Sec. 6.2.1)"),
    "damping": Field(float, **POSITIVE, doc="N*s/m, the ankle damper beside it"),
}
"""``[robot.ankle]``: a compliant ankle on every leg, in either engine (docs/fidelity.md, open item 2)."""

SCHEMA: dict[str, Any] = {
    "name": Field(str, doc="scenario name"),
    "description": Field(str, "", doc="one line"),
    "paper": Field(str, "", doc="what it reproduces"),
    "t_end": Field(float, **POSITIVE, doc="s simulated"),
    "seed": Field(int, 0, lo=0, doc="random seed"),
    "robot": {
        "preset": Field(str, "yu-sim", choices=ROBOT_PRESETS, doc="geometry preset"),
        "engine": Field(str, "dart", choices=ROBOT_ENGINES, doc="physics engine of the plant (docs/engines.md)"),
        "native": Field(bool, True, doc="step the plant through its C step when one can be built (false: its "
                                        "Python step, the reference; same numbers, slower)"),
        **{k: Field(float, **POSITIVE, doc="geometry override (m, kg)") for k in GEOMETRY_KEYS},
        "kp": Field(float, **POSITIVE, doc="joint servo stiffness N*m/rad"),
        "kd": Field(float, **POSITIVE, doc="joint servo damping N*m*s/rad"),
        "friction": Field(float, **POSITIVE, doc="Coulomb friction of the robot's shapes"),
        "velocity_ff": Field(bool, doc="servo velocity feed-forward"),
        "mujoco": MUJOCO_SCHEMA,
        "dart": DART_SCHEMA,
        "ankle": ANKLE_SCHEMA,
    },
    "controller": {
        "kind": Field(str, "yu", choices=CONTROLLER_KINDS),
        "params": Field(dict, {}, doc="controller graph parameters by path"),
        # Yu
        "Fcx": Field(float, lo=0.0, doc="N, lateral obstacle threshold (Y8)"),
        "Fcy": Field(float, lo=0.0, doc="N, forward obstacle threshold (Y8)"),
        "Fcz": Field(float, lo=0.0, doc="N, touchdown threshold (Y9)"),
        "clearance_elevator": Field(float, **POSITIVE, doc="m, swing clearance of an elevator reflex (Y11)"),
        "gait": Field(int, lo=1, hi=3, doc="1 tripod, 2 tetrapod, 3 wave (Y16)"),
        # Fukuhara
        "setting": Field(int, lo=1, hi=3, doc="speed setting 1, 2, 3 = (pi/3, pi/3), (pi/3, pi/6), (pi/3, pi/15)"),
        "case": Field(int, lo=0, hi=2, doc="amputation: 0 none, 1 L2+R2, 2 L1+R1"),
        "transient": Field(float, lo=0.0, doc="s before the gait classifier's window"),
    },
    "terrain": {
        "friction": Field(float, 1.0, **POSITIVE, doc="ground Coulomb friction"),
        "jitter_m": Field(float, 0.0, lo=0.0, doc="m, random shift of every feature's position_y"),
    },
    "criteria": {
        "no_fall": Field(bool, True, doc="success needs no fall (body contact or tilt over fall_tilt_deg)"),
        "fall_tilt_deg": Field(float, 45.0, **POSITIVE, hi=180.0),
        "max_tilt_deg": Field(float, 30.0, **POSITIVE, hi=180.0, doc="success needs max tilt below this"),
        "no_stall": Field(bool, True, doc="success needs no stall"),
        "stall_window_s": Field(float, 5.0, **POSITIVE, doc="s of walking (reflex waits excluded) ..."),
        "stall_progress_m": Field(float, 0.01, lo=0.0, doc="... with less forward progress than this is a stall"),
        "min_distance_m": Field(float, 0.0, lo=0.0, doc="success needs this forward distance"),
        "expected_gait": Field(str, "", doc="success needs this gait label ('' none, 'auto': by setting)"),
        "cross": Field(str, "", doc="success needs the body past this terrain feature's far edge + cross_margin_m"),
        "cross_margin_m": Field(float, 0.25, lo=0.0),
        "end_window_s": Field(float, 5.0, **POSITIVE, doc="the run's final window, reflex waits included"),
        "end_backslide_m": Field(float, 0.03, lo=0.0, doc="success needs the body not to slide back more in it"),
        "end_tilt_deg": Field(float, 15.0, lo=0.0, doc="success needs the tilt at the end below this"),
        "end_support": Field(bool, True, doc="success needs a statically stable support at some instant of the "
                             "last second"),
    },
    "aliases": Field(dict, {}, doc="short --set keys: alias = 'full.key'"),
    "disturbance": Field(list, [], doc="pushes on the body, [[disturbance]] tables: start_s, duration_s, "
                         "force_N = [fx, fy, fz] (world frame), point_m = [x, y, z] (body frame, optional)"),
}
SECTIONS = tuple(k for k, v in SCHEMA.items() if isinstance(v, dict))


@dataclass
class Scenario:
    """A validated scenario document and where it came from (for error messages)."""

    doc: dict[str, Any]
    source: str  # file path or "built-in NAME"
    text: str = ""  # the TOML text (to find the line of a key)
    overrides: dict[str, Any] = field(default_factory=dict)
    bare_keys: list[str] = field(default_factory=list)  # --set keys without a dot taken as controller keys

    @property
    def name(self) -> str:
        return self.doc["name"]

    def __getitem__(self, key: str) -> Any:
        return self.doc[key]

    def features(self) -> dict[str, dict[str, Any]]:
        """The terrain features ``{name: {type, ...}}`` in file order."""
        return {k: v for k, v in self.doc["terrain"].items() if isinstance(v, dict)}

    def to_toml(self) -> str:
        return dump_toml(self.doc)


# -- loading -----------------------------------------------------------------------------------------

def builtin_names() -> list[str]:
    """Names of the scenario files shipped in the package, in a stable order."""
    files = resources.files(BUILTIN_PACKAGE)
    return sorted(p.name[:-5] for p in files.iterdir() if p.name.endswith(".toml"))


def builtin_descriptions() -> dict[str, str]:
    return {n: load(n).doc.get("description", "") for n in builtin_names()}


def load(spec: str | Path, sets: Mapping[str, Any] | None = None) -> Scenario:
    """A built-in scenario by name or a ``.toml`` file, with ``sets`` overrides applied, validated."""
    text, source = _read(spec)
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"{source}: not valid TOML: {exc}") from None
    scenario = Scenario(raw, source, text)
    validate(scenario)
    for key, value in (sets or {}).items():
        apply_override(scenario, key, value)
    if sets:
        validate(scenario, overridden=True)
    return scenario


def _read(spec: str | Path) -> tuple[str, str]:
    spec_s = str(spec)
    if spec_s.endswith(".toml") or "/" in spec_s or Path(spec_s).suffix:
        path = Path(spec_s)
        if not path.is_file():
            raise ScenarioError(f"scenario file {path} does not exist")
        try:
            return path.read_text(encoding="utf-8"), str(path)
        except (OSError, UnicodeDecodeError) as exc:
            raise ScenarioError(f"cannot read scenario file {path}: {exc}") from None
    if spec_s not in builtin_names():
        raise ScenarioError(f"unknown scenario {spec_s!r} (built-in: {', '.join(builtin_names())}; "
                            f"or give a FILE.toml){did_you_mean(spec_s, builtin_names())}")
    res = resources.files(BUILTIN_PACKAGE) / f"{spec_s}.toml"
    return res.read_text(encoding="utf-8"), f"{BUILTIN_SOURCE}{spec_s}"


# -- validation --------------------------------------------------------------------------------------

BUILTIN_SOURCE = "built-in scenario "
"""How a built-in scenario names its source in messages (its file is the package's, not the user's)."""


def _where(scenario: Scenario, key: str, overridden: bool) -> str:
    """Where ``key`` came from, for a message: the ``--set`` the user typed for it (or for a key inside it),
    else the line of the user's own file; a built-in scenario's own text has no line the user wrote."""
    typed = [k for k in scenario.overrides if k == key or k.startswith(key + ".")]
    if typed:
        return f" (--set {', --set '.join(typed)}, {scenario.source})"
    if scenario.source.startswith(BUILTIN_SOURCE):
        return f" ({scenario.source})"
    line = line_of(scenario.text, key)
    return f" ({scenario.source}{f', line {line}' if line else ''})"


def line_of(text: str, key: str) -> int | None:
    """The line of ``text`` where dotted ``key`` is written (``[table]`` headers tracked), if found."""
    def parts(dotted: str) -> list[str]:  # split at the dots outside quotes (TOML: "*.eps" is one key)
        return [p.strip().strip('"') for p in re.split(r"\.(?=(?:[^\"]*\"[^\"]*\")*[^\"]*$)", dotted)]

    table: list[str] = []
    wanted = ".".join(parts(key))  # compared as joined text: a path given with or without the quotes
    for n, raw in enumerate(text.splitlines(), 1):
        line = raw.split("#", 1)[0].strip()
        m = re.fullmatch(r"\[+\s*([^\]]+?)\s*\]+", line)
        if m:
            table = parts(m.group(1))
            if ".".join(table) == wanted:
                return n
            continue
        m = re.match(r'("[^"]*"|[A-Za-z0-9_\-.]+)\s*=', line)
        if m and ".".join(table + parts(m.group(1))) == wanted:
            return n
    return None


_PLAIN_NAME = re.compile(r"[A-Za-z0-9_][A-Za-z0-9._-]{0,99}")


def validate(scenario: Scenario, overridden: bool = False) -> None:
    """Check every key against :data:`SCHEMA`; fill defaults; raise :class:`ScenarioError` naming the key."""
    doc = scenario.doc
    for key in doc:
        if key not in SCHEMA:
            raise ScenarioError(f"unknown key {key!r}{_where(scenario, key, overridden)}: known keys are "
                                + ", ".join(SCHEMA) + did_you_mean(key, SCHEMA))
    for key, spec in SCHEMA.items():
        if isinstance(spec, dict):
            table = doc.setdefault(key, {})
            if not isinstance(table, dict):
                raise ScenarioError(f"{key} must be a table{_where(scenario, key, overridden)}")
            _validate_table(scenario, key, table, spec, overridden)
        elif key in doc:
            doc[key] = spec.check(key, doc[key], _where(scenario, key, overridden))
        elif spec.default is not None:
            doc[key] = spec.default.copy() if isinstance(spec.default, (dict, list)) else spec.default
        elif key == "name" or (key == "t_end" and doc.get("controller", {}).get("kind") != "fukuhara"):
            raise ScenarioError(f"missing key {key!r} ({scenario.source})")  # fukuhara: t_end by speed setting
    if not _PLAIN_NAME.fullmatch(str(doc["name"])) or doc["name"] in (".", ".."):
        raise ScenarioError(f"name = {_show(doc['name'])} must be a plain name (letters, digits, '.', '_', '-'; "
                            f"no path: the default output is runs/<name>){_where(scenario, 'name', overridden)}")
    for alias, target in doc["aliases"].items():
        if not isinstance(target, str):
            raise ScenarioError(f"aliases.{alias} must be a string key, got {_show(target)}"
                                f"{_where(scenario, 'aliases.' + alias, overridden)}")
    _check_params(scenario, overridden)
    _check_features(scenario, overridden)
    _check_disturbances(scenario, overridden)
    crit = doc["criteria"]
    if crit["cross"] and crit["cross"] not in scenario.features():
        raise ScenarioError(f"criteria.cross = {crit['cross']!r} names no terrain feature "
                            f"(features: {', '.join(scenario.features()) or 'none'})"
                            f"{_where(scenario, 'criteria.cross', overridden)}")


def _validate_table(scenario: Scenario, name: str, table: dict, spec: dict, overridden: bool) -> None:
    for key, value in list(table.items()):
        full = f"{name}.{key}"
        if name == "terrain" and isinstance(value, dict):
            continue  # a feature, checked by _check_features
        if isinstance(spec.get(key), dict):  # a sub-table ([robot.mujoco])
            if not isinstance(value, dict):
                raise ScenarioError(f"{full} must be a table{_where(scenario, full, overridden)}")
            _validate_table(scenario, full, value, spec[key], overridden)
            continue
        if key not in spec:
            known = ", ".join(spec) + (", or a feature table [terrain.NAME]" if name == "terrain" else "")
            raise ScenarioError(f"unknown key {full!r}{_where(scenario, full, overridden)}: known keys of "
                                f"[{name}] are {known}{did_you_mean(key, spec)}")
        f = spec[key]
        if f.kind is dict:
            if not isinstance(value, dict):
                raise ScenarioError(f"{full} must be a table{_where(scenario, full, overridden)}")
            continue
        table[key] = f.check(full, value, _where(scenario, full, overridden))
    for key, f in spec.items():
        if isinstance(f, dict):
            continue  # a sub-table: its defaults are its reader's (robot.mujoco: ContactModel)
        if key not in table and f.default is not None:
            table[key] = f.default.copy() if isinstance(f.default, dict) else f.default


def _check_params(scenario: Scenario, overridden: bool) -> None:
    for key, value in scenario.doc["controller"]["params"].items():
        full = f"controller.params.{key}"
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise ScenarioError(f"controller parameter {key} must be a finite number, got {_show(value)}"
                                f"{_where(scenario, full, overridden)}")


def _check_features(scenario: Scenario, overridden: bool) -> None:
    from cpgsim.robots.terrain import FEATURES, ParameterError, compose

    feats = scenario.features()
    for name, feat in feats.items():
        where = f"terrain.{name}"
        if "type" not in feat and overridden:  # --set terrain.NAME.KEY on a feature the scenario lacks
            others = [n for n, f in feats.items() if "type" in f]
            raise ScenarioError(f"{where} is not a terrain feature of this scenario{did_you_mean(name, others)} "
                                f"(features: {', '.join(others) or 'none'}; to add one, also set {where}.type to "
                                f"one of {', '.join(FEATURES)})")
        if feat.get("type") not in FEATURES:
            raise ScenarioError(f"{where}.type must be one of {', '.join(FEATURES)}, got {_show(feat.get('type'))}"
                                f"{did_you_mean(str(feat.get('type')), FEATURES)}"
                                f"{_where(scenario, where + '.type', overridden)}")
    try:
        compose({f"terrain.{k}": v for k, v in feats.items()}, scenario.doc["terrain"]["friction"])
    except ParameterError as exc:
        key = re.search(r"terrain\.[\w\-]+(\.\w+)?", str(exc))  # the field when the message names one
        at = _where(scenario, key.group(0), overridden) if key else f" ({scenario.source})"
        raise ScenarioError(f"{exc}{at}") from None


def _check_disturbances(scenario: Scenario, overridden: bool) -> None:
    from cpgsim.robots.disturbance import ParameterError, as_pushes

    try:
        as_pushes(scenario.doc["disturbance"])
    except ParameterError as exc:
        raise ScenarioError(f"{exc}{_where(scenario, 'disturbance', overridden)}") from None


# -- overrides ---------------------------------------------------------------------------------------

def parse_value(text: str) -> Any:
    """A ``--set`` value: a TOML value (``0.06``, ``true``, ``[1, 2]``, ``"x"``); a bare word is a string."""
    text = text.strip()
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        if re.fullmatch(r"[A-Za-z_][\w\-+]*", text):
            return text
        raise ScenarioError(f"value {text!r} is not a TOML value (number, true/false, \"string\", [list])") from None


def resolve_key(scenario: Scenario, key: str) -> list[str]:
    """The document path a ``--set`` key names (aliases, controller parameters)."""
    key = key.strip()
    if not key:
        raise ScenarioError("empty --set key")
    if "." not in key:
        target = scenario.doc.get("aliases", {}).get(key)
        if target:
            return target.split(".")
        if key in SCHEMA and not isinstance(SCHEMA[key], dict):
            return [key]
        scenario.bare_keys.append(key)
        key = f"controller.{key}"
    parts = key.split(".")  # two parts at least: the key holds a dot here
    if parts[0] == "controller" and parts[1] not in SCHEMA["controller"]:
        return ["controller", "params", ".".join(parts[1:])]
    if parts[0] == "terrain" and len(parts) > 3:
        raise ScenarioError(f"--set {key}: terrain keys are terrain.KEY or terrain.FEATURE.FIELD")
    return parts


def scenario_keys(scenario: Scenario) -> list[str]:
    """The keys a bare ``--set KEY`` can mean besides a controller parameter: the scenario's top-level
    values, its aliases and the controller table's own keys."""
    keys = ([k for k, f in SCHEMA.items() if not isinstance(f, dict)] + list(scenario.doc.get("aliases", {}))
            + [k for k in SCHEMA["controller"] if k != "params"])
    return list(dict.fromkeys(keys))


def bare_key_error(scenario: Scenario, exc: Exception) -> ScenarioError | None:
    """A clearer error for a failed build caused by a bare ``--set`` key that is not a controller parameter:
    when the key is close to a scenario key (``t_ned`` for ``t_end``), the suggestion comes from there, not
    from the controller's parameters (None when no bare key is behind ``exc``)."""
    import difflib

    text = str(exc)
    for key in scenario.bare_keys:
        if f"controller.{key}" not in text and repr(key) not in text:
            continue
        close = difflib.get_close_matches(key, scenario_keys(scenario), n=3, cutoff=0.6)
        if close:
            hint = " or ".join(repr(c) for c in close)
            return ScenarioError(f"--set {key}: no scenario key or controller parameter {key!r}; did you mean {hint}? "
                                 f"(scenario keys: {', '.join(scenario_keys(scenario))}; controller parameters are "
                                 f"paths such as controller.L1.sensors.Fcx)")
    return None


def apply_override(scenario: Scenario, key: str, value: Any) -> None:
    """Set ``key`` (a ``--set`` key) to ``value`` (a Python value: the CLI parses its text with
    :func:`parse_value` first)."""
    path = resolve_key(scenario, key)
    node = scenario.doc
    for part in path[:-1]:
        if part not in node:
            if path[0] in SECTIONS:  # (this loop runs only for a path of two parts or more)
                node[part] = {}
            else:
                raise ScenarioError(f"--set {key}: unknown key {'.'.join(path)!r}{did_you_mean(path[0], SCHEMA)} "
                                    f"(known top-level keys: {', '.join(SCHEMA)})")
        node = node[part]
        if not isinstance(node, dict):
            raise ScenarioError(f"--set {key}: {part} is not a table")
    node[path[-1]] = value
    scenario.overrides[".".join(path)] = value
    scenario.overrides[key] = value


# -- writing -----------------------------------------------------------------------------------------

def _show(value: Any) -> str:
    return f"{type(value).__name__} {value!r}" if not isinstance(value, str) else repr(value)


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        return repr(v)
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if isinstance(v, dict):  # an inline table (the tables of a list such as disturbance)
        return "{" + ", ".join(f"{_toml_key(k)} = {_toml_value(x)}" for k, x in v.items()) + "}"
    raise ScenarioError(f"cannot write {v!r} as TOML")


def _toml_key(k: str) -> str:
    return k if re.fullmatch(r"[A-Za-z0-9_\-]+", k) else _toml_value(k)


def dump_toml(doc: Mapping[str, Any]) -> str:
    """The resolved scenario as TOML (what ``cpgsim run NAME --show`` prints)."""
    lines: list[str] = []

    def table(prefix: list[str], t: Mapping[str, Any]) -> None:
        scalars = {k: v for k, v in t.items() if not isinstance(v, dict)}
        subs = {k: v for k, v in t.items() if isinstance(v, dict)}
        if prefix and (scalars or not subs):
            lines.append("")
            lines.append("[" + ".".join(_toml_key(p) for p in prefix) + "]")
        for k, v in scalars.items():
            lines.append(f"{_toml_key(k)} = {_toml_value(v)}")
        for k, v in subs.items():
            table([*prefix, k], v)

    table([], doc)
    return "\n".join(lines).lstrip("\n") + "\n"
