"""Fukuhara 2022 experiments as ``cpgsim run`` scenarios: gaits, amputation, gap crossing.

Every scenario is the ``fukuhara-controller`` graph (:mod:`cpgsim.components.fukuhara.controller`) closed
around the DART hexapod (YU_SIM geometry) at 1 kHz, started with a random alpha per leg drawn from
``--seed`` (uniform in ``[theta_PEP, theta_AEP]``, every leg in LateStance, the robot standing on
its feet in that posture after a 0.3 s settle).

``--set`` keys (values are numbers):

- scenario options, without a dot: ``setting`` (1, 2, 3 = ``(omega_sw, omega_st)`` of ``(pi/3, pi/3)``,
  ``(pi/3, pi/6)``, ``(pi/3, pi/15)``), ``case`` (amputation: 1 = L2+R2, 2 = L1+R1), ``gap_width``,
  ``gap_y`` (m), ``transient`` (s, start of the gait classifier's window);
- any controller parameter, without a dot, for all legs: ``rule2=0``, ``omega_st=0.4``, ``theta_DRT=-0.45``,
  ``N_ALS=2``, ``h_sw=0.05`` (see docs/fukuhara.md);
- a dotted path, for one parameter of the graph: ``ctrl.L1.theta_AEP=0.5``, ``robot.kp=150``.

The summary (``summary.json``) adds: the gait report of :mod:`cpgsim.experiments.gait_classifier` (label, duty
factors, phase lags, rule), the same classification on the foot contacts, rule counts, walking speed,
``success`` (per scenario, see below) and the picture ``alpha.png`` (alpha and mode per leg, Fukuhara
Figure 7D-F).

Success: ``fukuhara-gaits`` -- no fall and the expected gait label of the speed setting;
``fukuhara-amputation`` -- no fall and at least 0.1 m forward; ``fukuhara-gap`` -- see :func:`gap`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from cpgsim.components.core import ModelError, did_you_mean
from cpgsim.components.fukuhara.blocks import MODE_NAMES, RULE_SEARCH, SWING
from cpgsim.components.fukuhara.controller import (
    CONTROLLER_PARAMS,
    SPEED_SETTINGS,
    TRAJECTORY_PARAMS,
    describe_parameters,
    fukuhara_controller,
    initial_joint_targets,
    leg_indices,
    set_initial,
)
from cpgsim.components.geometry import LEG_NAMES, YU_SIM, RobotGeometry
from cpgsim.components.graph import Graph
from cpgsim.experiments.gait_classifier import classify, stance_from_fz
from cpgsim.experiments.outcomes import crossing, fall
from cpgsim.experiments.scenario import Scenario, ScenarioError
from cpgsim.experiments.setup import (
    PLANT_KEYS,
    RunSetup,
    contact_model,
    engine_info,
    engine_of,
    leg_fields,
    robot_geometry,
    terrain_of,
)
from cpgsim.harness.results import Results
from cpgsim.robots.registry import make_plant
from cpgsim.robots.terrain import Terrain

EXPECTED_GAIT = {1: "tripod", 2: "tetrapod", 3: "wave"}
AMPUTATION_CASES = {1: ("L2", "R2"), 2: ("L1", "R1")}
SETTLE = 0.3  # s of standing before t = 0
FZ_CONTACT = 1.0  # N, foot contact threshold of the contact-based gait pattern
GAP_MARGIN = 0.25  # m the body centre must pass beyond the gap's far edge
MIN_WALK = 0.1  # m forward for the amputation scenario to count as walking
DEFAULT_T_END = {1: 30.0, 2: 40.0, 3: 45.0}
DEFAULT_TRANSIENT = {1: 15.0, 2: 15.0, 3: 15.0}


# -- building ------------------------------------------------------------------------------------

def _split_sets(sets: dict[str, float], options: dict[str, float]) -> tuple[dict, dict, dict]:
    """(scenario options, controller parameters for all legs, dotted parameter paths)."""
    opts, ctrl, paths = dict(options), {}, {}
    for key, value in sets.items():
        if "." in key:
            paths[key] = value
        elif key in options:
            opts[key] = value
        elif key in CONTROLLER_PARAMS or key in TRAJECTORY_PARAMS:
            ctrl[key] = value
        else:
            hint = did_you_mean(key, [*options, *CONTROLLER_PARAMS, *TRAJECTORY_PARAMS])
            raise ModelError(f"unknown --set key {key!r}{hint}"
                             f": use a scenario option ({', '.join(options)}), a controller "
                             f"parameter ({', '.join(CONTROLLER_PARAMS + TRAJECTORY_PARAMS[:3])}) or a dotted "
                             "path like ctrl.L1.theta_AEP / robot.kp")
    return opts, ctrl, paths


def _setting(value: float) -> int:
    s = int(round(value))
    if s not in SPEED_SETTINGS or s != value:
        raise ModelError(f"setting must be 1, 2 or 3 (tripod, tetrapod, wave speeds), got {value:g}")
    return s


def initial_alpha(seed: int | None, geometry: RobotGeometry = YU_SIM) -> np.ndarray:
    """Random initial alpha per leg, uniform in [-alpha_max, alpha_max], from ``seed`` (default 0)."""
    rng = np.random.default_rng(0 if seed is None else int(seed))
    return rng.uniform(-geometry.alpha_max, geometry.alpha_max, 6)


def closed_loop(name: str, sets: dict[str, float], seed: int | None, options: dict[str, float],
                amputated: tuple[str, ...] = (), terrain: Terrain | None = None,
                geometry: RobotGeometry = YU_SIM, engine: str = "dart",
                contact=None) -> tuple[Graph, dict, dict, np.ndarray]:
    """Controller + plant graph (``engine``: ``"dart"`` or ``"mujoco"``, ``contact`` MuJoCo's
    :class:`~cpgsim.robots.mujoco.mjcf.ContactModel` or ``None``); returns (graph, scenario options, controller
    overrides, initial alpha)."""
    opts, ctrl_params, paths = _split_sets(sets, options)
    setting = _setting(opts.get("setting", 1))
    omega_sw, omega_st = SPEED_SETTINGS[setting]
    ctrl_params = {"omega_sw": omega_sw, "omega_st": omega_st, **ctrl_params}
    cut = leg_indices(amputated)
    ctrl = fukuhara_controller("ctrl", geometry, amputated=cut, **ctrl_params)
    alpha0 = initial_alpha(seed, geometry)
    set_initial(ctrl, alpha0)
    q0 = initial_joint_targets(geometry, alpha0, cut)
    robot = make_plant(engine, "robot", amputated=tuple(cut), geometry=geometry, terrain=terrain, q0=q0,
                       settle=SETTLE, contact=contact)
    g = Graph(name.replace("-", "_"), f"Fukuhara controller + {engine} hexapod ({name})")
    g.add(ctrl)
    g.add(robot)
    g.connect("ctrl.q_target", "robot.q_target")
    g.connect("robot.toe_force", "ctrl.toe_force")
    for path, value in paths.items():
        g.set_param(path, value)
    opts["setting"] = setting
    return g, opts, ctrl_params, alpha0


def _info(graph: Graph, seed: int | None, opts: dict, alpha0: np.ndarray, amputated: tuple[str, ...]) -> dict:
    ctrl = graph.find("ctrl")
    return {"seed": 0 if seed is None else int(seed), "options": dict(opts),
            "amputated": list(amputated), "initial_alpha_rad": [float(a) for a in alpha0],
            "controller": describe_parameters(ctrl)}


def _record(amputated: tuple[str, ...]) -> list[str]:
    """Recorded columns: what the summary, the classifier and the run pictures read (not ``robot.qd``)."""
    return ["robot.q", "robot.toe_force", "robot.body_*", "robot.foot_position", "ctrl.*.alpha", "ctrl.*.mode",
            "ctrl.*.rule"]


# -- analysis ------------------------------------------------------------------------------------

def mode_stance(res: Results, legs: list[int] | None = None) -> np.ndarray:
    """Stance per leg from the controller modes (time x 6; missing legs: False)."""
    out = np.zeros((len(res.time), 6), dtype=bool)
    for i, leg in enumerate(LEG_NAMES):
        col = f"ctrl.{leg}.mode"
        if col in res and (legs is None or i in legs):
            out[:, i] = res[col] > SWING + 0.5
    return out


def contact_stance(res: Results) -> np.ndarray:
    f = res["robot.toe_force"].reshape(len(res.time), 6, 3)
    return stance_from_fz(f[:, :, 2], FZ_CONTACT)


def rule_events(res: Results) -> dict[str, dict[str, int]]:
    """How often each rule switched each leg's mode."""
    names = {1: "rule1_AEP", 11: "rule1_PEP", 2: "rule2_search", 3: "rule3_load", 4: "rule4_coupling",
             5: "foothold"}
    out = {}
    for leg in LEG_NAMES:
        col = f"ctrl.{leg}.rule"
        if col in res:
            r = res[col]
            out[leg] = {n: int(np.count_nonzero(r == k)) for k, n in names.items()}
    return out


MAX_LISTED_EVENTS = 20


def searching_events(res: Results) -> list[dict]:
    """The first 20 rule-2 (searching reflex) events as run 'reflexes' (leg, kind, t, force_N = forward
    force); ``rule_events`` in the summary counts all of them."""
    out = []
    f = res["robot.toe_force"].reshape(len(res.time), 6, 3)
    for i, leg in enumerate(LEG_NAMES):
        col = f"ctrl.{leg}.rule"
        if col in res:
            for k in np.flatnonzero(res[col] == RULE_SEARCH):
                out.append(leg_fields(i) | {"kind": "searching", "t": float(res.time[k]), "force_N": float(f[k, i, 1])})
    return sorted(out, key=lambda e: e["t"])[:MAX_LISTED_EVENTS]


def gait_summary(res: Results, legs: list[int], transient: float) -> dict[str, Any]:
    """Gait reports from the controller modes (the label used) and from the foot contacts."""
    t_start = min(transient, float(res.time[-1]) * 0.5)
    by_mode = classify(res.time, mode_stance(res, legs), t_start=t_start, legs=legs)
    by_mode.rule = by_mode.rule.replace("stance = Fz > 1 N", "stance = controller mode EarlyStance/LateStance")
    by_contact = classify(res.time, contact_stance(res), t_start=t_start, legs=legs, fz_contact=FZ_CONTACT)
    pos = res["robot.body_position"]
    keep = res.time >= t_start
    speed = (float((pos[keep][-1, 1] - pos[keep][0, 1]) / (res.time[keep][-1] - res.time[keep][0]))
             if keep.sum() > 1 else float("nan"))
    return {"gait": by_mode.label, "gait_report": by_mode.as_dict(), "gait_from_contacts": by_contact.label,
            "gait_report_contacts": by_contact.as_dict(), "speed_m_s": speed, "rule_events": rule_events(res)}


def plot_alpha(res: Results, path: Path, title: str) -> Path:
    """Alpha target per leg with swing (white) / EarlyStance (light) / LateStance (grey) bands."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = res.time
    fig, axes = plt.subplots(6, 1, figsize=(11, 8.5), sharex=True)
    colors = {1: "#c6dbef", 2: "0.75"}
    for ax, leg in zip(axes, LEG_NAMES, strict=True):
        col = f"ctrl.{leg}.alpha"
        if col not in res:
            ax.text(0.5, 0.5, f"{leg} amputated", transform=ax.transAxes, ha="center", va="center")
            ax.set_ylabel(leg)
            continue
        m = res[f"ctrl.{leg}.mode"]
        for mode, color in colors.items():
            on = np.r_[0, (m == mode).astype(int), 0]
            d = np.diff(on)
            for a, b in zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1), strict=True):
                ax.axvspan(t[a], t[min(b, len(t) - 1)], color=color, lw=0)
        ax.plot(t, res[col], color="k", lw=0.8)
        r = res[f"ctrl.{leg}.rule"]
        for k, (marker, c) in {2: ("v", "tab:blue"), 3: ("^", "tab:red"), 4: ("x", "tab:green")}.items():
            idx = np.flatnonzero(r == k)
            if len(idx):
                ax.plot(t[idx], res[col][idx], marker, color=c, ms=4, ls="none")
        ax.set_ylabel(f"{leg}\nalpha [rad]", fontsize=8)
    for marker, c, text in (("v", "tab:blue", "rule 2 search"), ("^", "tab:red", "rule 3 load"),
                            ("x", "tab:green", "rule 4 coupling")):
        axes[0].plot([], [], marker, color=c, ls="none", label=text)
    axes[0].legend(loc="lower right", bbox_to_anchor=(1.0, 1.0), ncol=3, fontsize=7, frameon=False)
    axes[0].set_title(title + "\n(white: Swing, blue: EarlyStance, grey: LateStance)", loc="left", fontsize=9)
    axes[-1].set_xlabel("time [s]")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def _stance_fn(legs: list[int]):
    return lambda res: mode_stance(res, legs)


def _thresholds(ctrl_params: dict) -> dict[str, float]:
    from cpgsim.components.fukuhara.blocks import DEFAULTS

    # "Fcz" is drawn as a line on the Fz plot (rule 3's N_ALS); N_SRH applies to |(Fx, Fy)|, listed only
    return {"Fcz": float(ctrl_params.get("N_ALS", DEFAULTS["N_ALS"])),
            "N_SRH": float(ctrl_params.get("N_SRH", DEFAULTS["N_SRH"]))}


# -- the scenario builder ---------------------------------------------------------------------------

def _sets_of(scenario: Scenario) -> dict[str, Any]:
    """The ``closed_loop`` overrides of a scenario: controller table keys, graph paths, plant keys."""
    ctrl = scenario.doc["controller"]
    sets: dict[str, Any] = {k: float(ctrl[k]) for k in ("setting", "transient") if k in ctrl}
    for key, value in ctrl["params"].items():
        if "." in key or "*" in key:
            sets[f"ctrl.{key}"] = float(value)
        elif key in CONTROLLER_PARAMS or key in TRAJECTORY_PARAMS:
            sets[key] = float(value)
        else:
            raise ScenarioError(f"unknown key controller.{key} for a fukuhara controller"
                                f"{did_you_mean(key, CONTROLLER_PARAMS + TRAJECTORY_PARAMS)}: use setting, case, "
                                f"transient, a controller parameter ({', '.join(CONTROLLER_PARAMS)}; "
                                f"{', '.join(TRAJECTORY_PARAMS)}) or a graph path like controller.L1.theta_AEP "
                                f"({scenario.source})")
    robot = scenario.doc["robot"]
    sets.update({f"robot.{k}": float(robot[k]) for k in PLANT_KEYS if k in robot})
    return sets


def build(scenario: Scenario) -> RunSetup:
    """The closed loop of a ``kind = "fukuhara"`` scenario: gaits by speed setting (Fukuhara 3.1),
    amputation (``controller.case``, 3.2), gap crossing (``criteria.cross`` names the gap, 3.3)."""
    doc = scenario.doc
    ctrl_table, crit = doc["controller"], doc["criteria"]
    geometry = robot_geometry(scenario)
    terrain = terrain_of(scenario, geometry)
    case = int(ctrl_table.get("case", 0))
    amputated = AMPUTATION_CASES.get(case, ())
    seed = int(doc["seed"])
    opts0 = {"setting": 1.0, "transient": 15.0}
    contact = contact_model(scenario)
    try:
        graph, opts, ctrl_params, alpha0 = closed_loop(scenario.name, _sets_of(scenario), seed, opts0,
                                                       amputated=amputated, terrain=terrain, geometry=geometry,
                                                       engine=engine_of(scenario),
                                                       contact=contact)
    except ScenarioError:
        raise
    except ModelError as exc:
        raise ScenarioError(f"{scenario.name}: {exc} ({scenario.source})") from None
    setting, transient = opts["setting"], float(opts["transient"])
    custom_speed = any(k in ctrl_params and ctrl_params[k] != v
                       for k, v in zip(("omega_sw", "omega_st"), SPEED_SETTINGS[setting], strict=True))
    expected = crit["expected_gait"] or None
    if expected == "auto":
        expected = None if custom_speed else EXPECTED_GAIT[setting]
    legs = [i for i in range(6) if LEG_NAMES[i] not in amputated]
    info = {**_info(graph, seed, opts, alpha0, amputated), **engine_info(scenario, contact)}
    info.update({"omega_sw": ctrl_params["omega_sw"], "omega_st": ctrl_params["omega_st"],
                 "rule2": float(ctrl_params.get("rule2", 1.0)), "expected_gait": expected})
    cross = scenario.features().get(crit["cross"]) if crit["cross"] else None
    far_edge = None
    if cross is not None:
        feat = terrain.params["features"][crit["cross"]]
        width = feat.get("width", feat.get("length", 0.0))
        far_edge = feat["position_y"] + width
        info["gap"] = {"y": feat["position_y"], "width": width}
        info["success_rule"] = (f"body centre reaches y >= {crit['cross']} far edge + {crit['cross_margin_m']} m "
                                "before any fall")

    def extra(res: Results, out: Path) -> dict[str, Any]:
        s = gait_summary(res, legs, transient)
        checks: dict[str, bool] = {}
        if expected is not None:
            checks["expected_gait"] = s["gait"] == expected
            s["expected_gait"] = expected
        if amputated:
            pos = res["robot.body_position"]
            s["walks"] = bool(not fall(res, "robot")[0] and pos[-1, 1] - pos[0, 1] >= MIN_WALK)
        if far_edge is not None:
            crossing = gap_outcome(res, far_edge, crit["cross_margin_m"])
            checks["cross"] = crossing.pop("success")
            s.update({k: v for k, v in crossing.items() if not k.startswith("fell")})
        verdict = "ok" if all(checks.values()) else "failed"
        s["more_pictures"] = []
        if out is not None:  # None: no pictures (a benchmark's trial)
            s["more_pictures"] = [plot_alpha(res, out / "alpha.png", f"{scenario.name} (setting {setting}, rule 2 "
                                             f"{'on' if info['rule2'] else 'off'}"
                                             f"{', amputated ' + '+'.join(amputated) if amputated else ''}): gait "
                                             f"{s['gait']} (contacts: {s['gait_from_contacts']}), {verdict}").name]
        s["checks"] = checks
        return s

    t_end = float(doc["t_end"]) if doc.get("t_end") is not None else DEFAULT_T_END[setting]
    return RunSetup(graph=graph, geometry=geometry, terrain=terrain, t_end=t_end,
                    thresholds=_thresholds(ctrl_params), stance=_stance_fn(legs), reflexes=searching_events,
                    record=_record(amputated), info=info, extra=extra, scenario=scenario,
                    event_labels={"searching": "rule 2 search (EarlyStance -> Swing)"})


def gap_outcome(res: Results, far_edge: float, margin: float = GAP_MARGIN) -> dict[str, Any]:
    """Gap crossing criterion (:func:`cpgsim.experiments.outcomes.crossing`: the body centre reaches
    ``far_edge + margin`` before any fall), with the fall's time and reason."""
    fell, fell_t, reason = fall(res, "robot")
    return {**crossing(res, "robot", far_edge, margin), "fell": fell, "fell_time_s": fell_t, "fell_reason": reason}



__all__ = ["EXPECTED_GAIT", "MODE_NAMES", "build", "closed_loop", "gait_summary",
           "gap_outcome", "initial_alpha", "mode_stance"]
