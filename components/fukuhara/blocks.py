"""Fukuhara et al. 2022 limb controller as equation blocks (rules of eqs. 1-5, Appendix A foot
trajectory of eqs. 6-14).

Two blocks per leg, both pure CasADi equations (no Python-side state), so the whole six-leg
controller compiles to one CasADi step and can be exported as an FMU:

- :class:`LimbModeController` -- the control mode ``Swing`` / ``EarlyStance`` / ``LateStance`` as a
  discrete state switched at the 1 ms sampled step by rules 1-4 (each switchable), and the alpha
  joint target integrated from the target velocity (F6, F10) as a continuous state;
- :class:`FootTrajectory` -- the beta/gamma targets that put the foot on the stance line or the swing
  arc of Appendix A (F7-F9, F11-F14) for the current alpha.

Plus :class:`HeldLeg` (an amputated leg: a constant folded posture).

Mode encoding (integer output ``mode``): ``SWING = 0``, ``EARLY_STANCE = 1``, ``LATE_STANCE = 2``.

Transition rules, evaluated in this order at every sampled step from the states *before* the
update (``a`` = the leg's alpha target, ``N_h`` = magnitude of the horizontal ground force on the foot,
``N_v`` = vertical ground force, ``a_ant`` = the next anterior leg's alpha target):

=========== ================ ========================================================== =============
from        rule             condition                                                  to
=========== ================ ========================================================== =============
Swing       1 stretch (F1)   ``a >= theta_AEP``                                         EarlyStance
                                                                                        (LateStance
                                                                                        if rule 2 is
                                                                                        off: F5)
Swing       3 ALS (F3)       ``a > theta_ALS`` and ``N_v >= N_ALS``                     LateStance
EarlyStance 1 stretch (F1)   ``a <= theta_PEP``                                         Swing
EarlyStance 2 search (F2)    ``a < theta_SRH`` and ``N_h < N_SRH``                      Swing
EarlyStance (end of F2)      ``a < theta_SRH`` and ``N_h >= N_SRH`` (foothold found)    LateStance
LateStance  1 stretch (F1)   ``a <= theta_PEP``                                         Swing
LateStance  4 coupling (F4)  ``a_ant <= theta_DRT`` (input unconnected: never)          Swing
=========== ================ ========================================================== =============

The paper names no explicit EarlyStance -> LateStance transition (its Figure 2A is an image); the
row "end of F2" is our reading: the early stance is the window ``theta_SRH < a <= theta_AEP`` in
which the leg tests its foothold, and a leg that still has a driving force at ``theta_SRH`` keeps its
stance as a LateStance leg (a long step, Figure 4 C2). With rule 2 off, EarlyStance is only
reachable as a start value and is left at ``theta_SRH`` for LateStance.

Alpha integration. ``alpha`` is a continuous state with ``d alpha / dt = omega_sw`` in Swing and
``-omega_st`` in both stance modes (F6, F10; the mode is held during the step, so the RK4 step of
the harness integrates it exactly); at the sampled step it is clamped to ``[-alpha_limit,
alpha_limit]`` (a joint limit; it only acts if rule 1 is switched off). The rules read this
integrated alpha target, not the measured joint angle: the servo tracks it (the plant's alpha
joints follow their target within a few mrad), and the controller stays a closed, deterministic
function of the force inputs.

Searching force. Fukuhara's ``N_h`` is "the horizontal component of the GRF (driving force is
positive)". On this robot a foot that has a firm foothold at ``theta_SRH`` (ahead of its hip) pushes
*against* the motion (measured: forward force -2 to -8 N with 10-20 N vertical load), so the signed
forward force would call a loaded leg foothold-less and lift it. We therefore use the magnitude of
the horizontal force ``sqrt(Fx^2 + Fy^2)``: zero without ground contact (the case rule 2 is about),
several newtons on a foothold. It is low-pass filtered (time constant ``tau_SRH``, 50 ms): on flat
ground a loaded leg can be unloaded for a few milliseconds while the load moves to a neighbour, and
the unfiltered force read at that instant made a loaded leg search (measured in the tetrapod setting).
Rule 3 reads the vertical force unfiltered (touchdown is detected at once).

Rule 4 is level-triggered, exactly as F4 is written: a posterior leg in LateStance swings whenever
its anterior neighbour's alpha is at or below ``theta_DRT``.
"""

from __future__ import annotations

import math

import casadi as ca

from cpgsim.components.core import Block, Equations, Symbols

SWING, EARLY_STANCE, LATE_STANCE = 0, 1, 2
MODE_NAMES = ("Swing", "EarlyStance", "LateStance")
NO_ANTERIOR = 100.0
"""Default of the ``alpha_anterior`` input: an unconnected input (front legs, legs behind an amputated
leg) never satisfies rule 4's ``alpha_anterior <= theta_DRT``."""

# rule numbers recorded in the ``rule`` output at the step a transition happened
RULE_NONE, RULE_AEP, RULE_PEP, RULE_SEARCH, RULE_ALS, RULE_COUPLING, RULE_FOOTHOLD = 0, 1, 11, 2, 3, 4, 5

DEFAULTS: dict[str, float] = {
    "omega_sw": math.pi / 3,
    "omega_st": math.pi / 3,
    "theta_AEP": math.pi / 6,
    "theta_PEP": -math.pi / 6,
    "theta_SRH": 0.35,
    "theta_ALS": -0.35,
    "theta_DRT": -0.49,
    "N_SRH": 0.5,
    "N_ALS": 1.0,
}


class LimbModeController(Block):
    """One leg's control mode and alpha target (Fukuhara F1-F6, F10); see the module docstring.

    Inputs: ``grf`` (3, N: the ground force on the foot in the body frame, ``(lateral, forward,
    vertical)`` as the plant's ``toe_force``), ``alpha_anterior`` (rad, default
    :data:`NO_ANTERIOR`). Outputs: ``alpha`` (rad, the alpha joint target), ``mode`` (integer),
    ``rule`` (integer: the rule that switched the mode at this step, 0 if none; 1 = AEP, 11 = PEP,
    2 = search, 3 = active load sensing, 4 = anterior coupling, 5 = foothold found).
    """

    def declare(self) -> None:
        d = DEFAULTS
        self.add_parameter("omega_sw", d["omega_sw"], "rad/s", (0, math.inf), "alpha target velocity in swing "
                           "(F10)", strict=True)
        self.add_parameter("omega_st", d["omega_st"], "rad/s", (0, math.inf), "alpha retraction velocity in "
                           "stance (F6; the target velocity is -omega_st)", strict=True)
        self.add_parameter("theta_AEP", d["theta_AEP"], "rad", (-1.5, 1.5), "anterior extreme position (F1)")
        self.add_parameter("theta_PEP", d["theta_PEP"], "rad", (-1.5, 1.5), "posterior extreme position (F1)")
        self.add_parameter("theta_SRH", d["theta_SRH"], "rad", (-1.5, 1.5), "end of the early stance: foothold "
                           "test angle (F2)")
        self.add_parameter("theta_ALS", d["theta_ALS"], "rad", (-1.5, 1.5), "end of the blind sector of active "
                           "load sensing (F3)")
        self.add_parameter("theta_DRT", d["theta_DRT"], "rad", (-1.5, 1.5), "anterior leg's alpha that forces "
                           "this leg to swing (F4)")
        self.add_parameter("N_SRH", d["N_SRH"], "N", description="horizontal ground force that confirms a "
                           "foothold (F2)")
        self.add_parameter("N_ALS", d["N_ALS"], "N", description="vertical force that marks a loaded leg (F3)")
        for k, text in ((1, "stretch reflex at AEP/PEP (F1)"), (2, "searching reflex (F2)"),
                        (3, "active load sensing (F3)"), (4, "anterior coupling (F4)")):
            self.add_parameter(f"rule{k}", 1.0, "1", (0, 1), f"rule {k} on/off: {text}", kind="boolean")
        self.add_parameter("alpha_limit", 0.9, "rad", (0, 1.5), "clamp of the alpha target", strict=True)
        self.add_parameter("tau_SRH", 0.05, "s", (0, math.inf), "time constant of the low-pass filter on the "
                           "horizontal force read by rule 2", strict=True)
        self.add_input("grf", 3, "N", description="ground force on the foot, body frame (lateral, forward, "
                       "vertical)")
        self.add_input("alpha_anterior", 1, "rad", default=NO_ANTERIOR,
                       description="alpha target of the next anterior leg (rule 4)")
        self.add_state("alpha", 0.0, "rad", "alpha joint target (integrated target velocity)")
        self.add_state("n_h", 0.0, "N", "low-pass filtered horizontal ground force (rule 2)")
        self.add_discrete_state("mode", float(LATE_STANCE), "1", "0 Swing, 1 EarlyStance, 2 LateStance",
                                kind="integer")
        self.add_discrete_state("rule", 0.0, "1", "rule that switched the mode at the last step (0 none)",
                                kind="integer")
        self.add_output("alpha", 1, "rad", description="alpha joint target")
        self.add_output("mode", 1, "1", kind="integer", description="0 Swing, 1 EarlyStance, 2 LateStance")
        self.add_output("rule", 1, "1", kind="integer", description="rule that switched the mode at this step")

    def define(self, v: Symbols) -> Equations:
        p, a, mode = v.p, v.x["alpha"], v.z["mode"]
        f_h = ca.sqrt(v.u["grf"][0] ** 2 + v.u["grf"][1] ** 2)  # horizontal force magnitude (see docstring)
        n_h = v.x["n_h"]  # ... low-pass filtered
        n_v = v.u["grf"][2]
        on = [None] + [p[f"rule{k}"] > 0.5 for k in range(1, 5)]
        is_swing = mode < 0.5
        is_early = ca.logic_and(mode > 0.5, mode < 1.5)

        # each candidate: (condition, new mode, rule number); the first true one in each mode wins
        at_aep = ca.logic_and(on[1], a >= p["theta_AEP"])
        at_pep = ca.logic_and(on[1], a <= p["theta_PEP"])
        loaded = ca.logic_and(on[3], ca.logic_and(a > p["theta_ALS"], n_v >= p["N_ALS"]))
        past_srh = a < p["theta_SRH"]
        no_hold = ca.logic_and(on[2], n_h < p["N_SRH"])
        coupled = ca.logic_and(on[4], v.u["alpha_anterior"] <= p["theta_DRT"])
        aep_mode = ca.if_else(on[2], EARLY_STANCE, LATE_STANCE)

        def chain(cases, default_mode):
            m, r = default_mode, RULE_NONE
            for cond, new_mode, rule in reversed(cases):
                m = ca.if_else(cond, new_mode, m)
                r = ca.if_else(cond, rule, r)
            return m, r

        m_sw, r_sw = chain([(at_aep, aep_mode, RULE_AEP), (loaded, LATE_STANCE, RULE_ALS)], SWING)
        m_es, r_es = chain([(at_pep, SWING, RULE_PEP), (ca.logic_and(past_srh, no_hold), SWING, RULE_SEARCH),
                            (past_srh, LATE_STANCE, RULE_FOOTHOLD)], EARLY_STANCE)
        m_ls, r_ls = chain([(at_pep, SWING, RULE_PEP), (coupled, SWING, RULE_COUPLING)], LATE_STANCE)
        new_mode = ca.if_else(is_swing, m_sw, ca.if_else(is_early, m_es, m_ls))
        new_rule = ca.if_else(is_swing, r_sw, ca.if_else(is_early, r_es, r_ls))

        rate = ca.if_else(mode < 0.5, p["omega_sw"], -p["omega_st"])
        lim = p["alpha_limit"]
        return Equations(
            derivatives={"alpha": rate, "n_h": (f_h - n_h) / p["tau_SRH"]},
            outputs={"alpha": a, "mode": mode, "rule": v.z["rule"]},
            updates={"mode": new_mode, "rule": new_rule},
            resets={"alpha": ca.fmin(ca.fmax(a, -lim), lim)},
        )


def swing_height(alpha, theta_aep, theta_pep, h_sw):
    """F14 with amplitude ``h_sw``: ``h_sw cos(pi (alpha - mid) / (AEP - PEP))``, 0 outside [PEP, AEP].

    Works on floats and CasADi symbols.
    """
    mid = (theta_aep + theta_pep) / 2
    arg = math.pi * (alpha - mid) / (theta_aep - theta_pep)
    if isinstance(alpha, (ca.SX, ca.MX)) or isinstance(theta_aep, (ca.SX, ca.MX)):
        return h_sw * ca.fmax(0, ca.cos(ca.fmin(ca.fmax(arg, -math.pi / 2), math.pi / 2)))
    return h_sw * max(0.0, math.cos(max(-math.pi / 2, min(math.pi / 2, arg))))


def plane_ik(r, h, coxa, thigh, shank):
    """``(beta, gamma)`` for the foot at leg-plane point ``(r, h)`` (cpgsim convention, knee up).

    The same closed form as :func:`cpgsim.components.geometry.leg_ik_plane`, in CasADi: F7/F8 and F11/F12 are
    this two-link inverse kinematics for equal links and no coxa; here the links may differ and the
    coxa offset is subtracted. An unreachable point is clamped to the stretched/folded leg.
    """
    dx, dz = r - coxa, h
    c = (dx * dx + dz * dz - thigh**2 - shank**2) / (2 * thigh * shank)
    gamma = ca.acos(ca.fmin(ca.fmax(c, -1), 1))
    beta = ca.atan2(dz, dx) + ca.atan2(shank * ca.sin(gamma), thigh + shank * ca.cos(gamma))
    return beta, gamma


class FootTrajectory(Block):
    """Joint targets of one leg from its alpha target and mode (Fukuhara Appendix A, F7-F14).

    Stance (EarlyStance, LateStance): the foot on the line at height ``-H`` below the alpha joint and
    ``W`` out from it, i.e. leg-plane radius ``W / cos(alpha)`` (F9). Swing: the same radius, height
    ``-H + h(alpha)`` with ``h`` of F14 but amplitude ``h_sw`` (the paper's F14 uses ``H``: the foot
    would rise to the hip's height; see docs/fukuhara.md). Output ``q`` = ``(alpha, beta, gamma)``.
    """

    def declare(self) -> None:
        self.add_parameter("H", 0.12, "m", (0, math.inf), "height of the alpha joints above the stance line",
                           strict=True)
        self.add_parameter("W", 0.10, "m", (0, math.inf), "lateral distance of the stance line from the alpha "
                           "joint", strict=True)
        self.add_parameter("h_sw", 0.04, "m", (0, math.inf), "swing height (amplitude of F14)")
        self.add_parameter("theta_AEP", DEFAULTS["theta_AEP"], "rad", (-1.5, 1.5), "AEP (F14)")
        self.add_parameter("theta_PEP", DEFAULTS["theta_PEP"], "rad", (-1.5, 1.5), "PEP (F14)")
        self.add_parameter("L_coxa", 0.05, "m", (0, math.inf), "coxa length")
        self.add_parameter("L_thigh", 0.12, "m", (0, math.inf), "femur length (L_UPR)", strict=True)
        self.add_parameter("L_shank", 0.15, "m", (0, math.inf), "tibia length (L_BTM)", strict=True)
        self.add_input("alpha", 1, "rad", description="alpha joint target")
        self.add_input("mode", 1, "1", kind="integer", description="0 Swing, 1 EarlyStance, 2 LateStance")
        self.add_output("q", 3, "rad", description="joint targets (alpha, beta, gamma)")

    def define(self, v: Symbols) -> Equations:
        p, a = v.p, v.u["alpha"]
        r = p["W"] / ca.cos(a)
        lift = swing_height(a, p["theta_AEP"], p["theta_PEP"], p["h_sw"])
        h = -p["H"] + ca.if_else(v.u["mode"] < 0.5, lift, 0)
        beta, gamma = plane_ik(r, h, p["L_coxa"], p["L_thigh"], p["L_shank"])
        return Equations(outputs={"q": ca.vertcat(a, beta, gamma)})


class HeldLeg(Block):
    """An amputated leg: its joint targets held at a folded posture (parameters ``alpha, beta, gamma``)."""

    def declare(self) -> None:
        self.add_parameter("alpha", 0.0, "rad", (-1.5, 1.5), "alpha target")
        self.add_parameter("beta", 1.3, "rad", (-3.2, 3.2), "beta target (femur raised)")
        self.add_parameter("gamma", 2.6, "rad", (-3.2, 3.2), "gamma target (knee folded)")
        self.add_output("q", 3, "rad", description="joint targets (alpha, beta, gamma)")

    def define(self, v: Symbols) -> Equations:
        return Equations(outputs={"q": ca.vertcat(v.p["alpha"], v.p["beta"], v.p["gamma"])})
