"""Yu reflex logic of one leg (Yu 2019, Sec. 4, eqs. 10-15) and a settable neuron.

:class:`YuReflexLogic` turns the sensory flags and the leader's state into the leg's reflex mode,
the network's mode inputs (Y10, Y12, Y13), state resets and the converter mode. Everything is
sampled at the macro step (discrete states updated with ``casadi.if_else``).

Modes (same numbers as :mod:`cpgsim.components.yu.converter`): 0 nominal, 1 elevator retraction,
2 elevator forward stroke, 3 searching, 4 return to the AEP after a failed search.

Events at a sample ``t_k`` (``half``: the leader protracts, ``y1 > 0``; ``rate > 0``: the FSM lets
the leg's clock run):

=========== =================================================================================
event       condition -> effect
=========== =================================================================================
ERT         mode 0, ``half``, ``rate > 0``, ``x1_ob_min < x1 < x1_ob_max`` and a rising edge of
            ``lambda_ob`` (of the flag gated by these conditions; with ``ob_support_veto = 1``, default
            0 = Yu's rule, also not while ``support``: a swinging foot that the tilting body puts down on
            the ground feels a horizontal force too, but it is standing, not hitting; with
            ``ob_after_liftoff = 1``, default 0, only once the foot has left the ground in this
            swing (``landed`` cleared) and, with ``ob_clear_time`` > 0, its touchdown flag has been off
            that long:
            a foot dragged at lift-off is no obstacle) -> mode 1; leader reset
            ``y1 = -1`` keeping ``x1`` (Y10, through the neuron's ``y_reset``); followers frozen
            (rate 0) and cut from the leader (``lead_gain = 0``) while the leader retracts.
E1 end      mode 1 and ``y1 > 0`` (the leader turns forward at its new PEP) -> mode 2; followers
            set to their maximum ``(m, 0)`` and held there (rate 0: the foot moves forward at the
            raised apex) until the leader, normalised by its amplitude (``x1/A``, ``A =
            sqrt(x1^2 + (y1/omega1)^2)``: Y10 changes the amplitude), passes ``x1_apex``; then
            they run at ``rate_descent`` times the leg's rate, ``m -> a`` in the time the leader
            needs from ``x1_apex`` to its AEP (:func:`elevator_descent_rate`). Default ``x1_apex
            = -0.035`` (where the locked orbit has the followers at their maximum) with rate 1:
            the second half of the stroke is the nominal swing's descent on the raised set. A
            later ``x1_apex`` with the matching faster descent keeps the foot high until it is
            nearly over its AEP (the scenarios use 0.6 / 1.74: an obstacle met late in a swing is
            cleared too). Either way the foot stays high until it is past the obstacle's edge and
            lands on the AEP. (The first version ran the followers at half speed over the whole
            stroke: the foot then descended from the start of the stroke and was back at 40 mm --
            the step's height -- halfway, so on the DART robot it came down on the step's edge.)
E2 end      mode 2, ``y1 <= 0``, ``x1 > 0`` (new AEP) -> network set to the AEP state of the
            limit cycle ``(x1_peak, 0; a, y2_aep)`` (undoes the amplitude change of Y10);
            mode 0, or 3 if ``lambda_td = 0`` (SRT).
swing end   mode 0 and ``half`` falls (``x1 > 0``, ``y1`` crosses zero downward); with
            ``lambda_td = 0`` -> SRT: mode 3 (network in searching mode: omega x (0.5, 1.5, 1.5),
            ``lead_gain = 0``, Y12, Y13; converter Y14, Y15).
early TD    ``early_td``, mode 0 with ``half`` or mode 2, ``rate > 0``,
            ``x1_td_min < x1/A < x1_td_max`` (default 0 .. 0.95; ``A`` the leader's amplitude,
            1 on its limit cycle; in mode 2 no upper bound: after the elevator's late descent the
            foot meets the obstacle's top just before the AEP), the foot (input ``foot_h``,
            forward kinematics of the joint targets) at least ``early_h_min`` (10 mm) above the
            foothold the swing aims at, ``ground_h + aim_h`` (``ground_h = -H`` the nominal ground,
            input ``aim_h`` the converter's remembered foothold height, 0 without its height
            memory) and a rising edge of ``lambda_td and support`` (input ``support`` from the
            sensory neurons: the contact force points up, within 27 degrees -- a foot pressed
            against a step's face or edge is no foothold, it is left to the elevator) (the foot lands
            on something higher, e.g. a step) -> the swing ends here: network set to the AEP
            state, converter ``capture`` (the posture difference is kept through the stance,
            see the converter). The window and the
            height gate keep ordinary contacts out: on the DART robot the body sags a few mm
            and the feet touch down before the swing ends; freezing them at that first light
            contact made a diagonal leg lose its load and the FSM wait for ATD for ever.
found (sTD) mode 3 and ``lambda_td`` -> network set to the AEP state, ``capture``, mode 0.
            With ``found_support = 1`` (default 0 = Yu's rule: touchdown ends the search) also ``support``: a searching
            foot that touches a ditch's wall reads ``lambda_td = 1`` from friction (Y9 uses
            ``|Fz|``); taken for a foothold, the stance then began with the foot against the
            wall and it slid down. The scenarios set 1: the search goes on until the foot
            rests on something.
give up     mode 3 and the searching leader completes its period (``half`` falls again, 10 s on
            Table 1) without touchdown -> network set to the AEP state, mode 4 (the converter
            returns to the AEP angles within ``T_return`` and the leg waits); ``gaveup = 1``
            until the leg touches down or its next swing ends (the FSM counts it as supported).
return end  mode 4 and the leader's stance ends (``half`` rises) -> mode 0.
withdraw    (``withdraw = 1``; default 0 = Yu) Yu's foot "returns to its initial AEP waiting for
            high-level regulation"; in a tripod gait the next stance of that leg then leaves two
            feet on the ground and the body tips over (DART robot: 20 degrees, then reflexes on the
            swinging legs that the body put down, and a fall). The regulation chosen: the return
            counts as a running reflex (the FSM holds every other leg, the leg's network is
            frozen); ``T_return`` after the give-up, still without touchdown, the leg withdraws
            (mode 5): the converter steps the foot back onto the stance line behind the AEP and a
            touchdown with ``support`` there ends it like a found foothold (network on the AEP
            state, ``capture``, mode 0; the shifted stance and the fade of the next swing bring the
            foot back to its nominal path). No touchdown within ``withdraw_timeout`` -> mode 4
            without the hold (Yu's waiting leg).
=========== =================================================================================

The outputs feeding the network (gains, frequency scales, rates) are functions of the mode
*state*, so they are constant over the integration of a step; reset requests, the converter
command ``mode_cmd`` and ``swing`` are evaluated with this sample's events (the converter sees
the mode change at the very sample the network is reset, and holds its last output; the FSM sees
a swing end at once). ``mode``, ``reflex``, ``active`` and ``gaveup`` are the committed states
(recorded values never show an event before it happens).

Status outputs: ``landed`` (latched touchdown: set by ``lambda_td`` while the leg is not swinging
-- swing ended or stance -- and by an early touchdown or a found foothold; cleared when the foot
has no contact while the leg swings (``x1 > x1_lift``, past its PEP) or runs a reflex, i.e. at
lift-off; the FSM's ATD uses it, see
:mod:`cpgsim.components.yu.fsm`), ``swing`` (1 while the leg is in a swing, including the whole elevator
reflex), ``active`` (1 while a reflex runs: modes 1-3; from the mode state, so that the FSM's
clock rate, which reads it, does not feed back into the same sample), ``reflex`` (0 none,
1 elevator, 2 searching, 3 returning), ``gaveup``, ``mode``; event counters ``n_ert``, ``n_srt``,
``n_found``, ``n_early``, ``n_giveup`` (discrete states, so each event is visible in recorded
results).
"""

from __future__ import annotations

import functools

import casadi as ca

from cpgsim.components.core import Block, Equations, Symbols
from cpgsim.components.networks import TABLE1_OMEGA
from cpgsim.components.neurons import VanDerPolNeuron
from cpgsim.components.yu.converter import (
    ELEV_FORWARD,
    ELEV_RETRACT,
    NOMINAL,
    RETURNING,
    SEARCHING,
    WITHDRAW,
    LockedOrbit,
    locked_orbit,
    swing_half,
)


def elevator_descent_rate(x1_apex: float, eps: float = 0.1, b: float = 4.0,
                          omega: tuple[float, float, float] = TABLE1_OMEGA, k: float = 0.1) -> float:
    """Follower time scale for the elevator's forward stroke held until ``x1_apex``: the locked orbit's
    time from the followers' maximum to the AEP over the leader's time from ``x1 = x1_apex`` (in swing) to
    the AEP, so the followers reach ``a`` when the leader reaches its AEP."""
    import math

    import numpy as np

    x1_peak, t, x1, y1, x2 = _descent_orbit(float(eps), float(b), tuple(float(w) for w in omega), float(k))
    sw = np.flatnonzero(y1 > 0)
    t_end = t[sw[-1]]
    t_max = t[sw[np.argmax(x2[sw])]]
    later = sw[x1[sw] >= x1_apex * x1_peak]
    if not later.size or not math.isfinite(x1_apex):
        raise ValueError(f"x1_apex = {x1_apex} is not reached in a swing")
    return float((t_end - t_max) / max(t_end - t[later[0]], 1e-9))


@functools.lru_cache(maxsize=32)
def _descent_orbit(eps: float, b: float, omega: tuple[float, float, float], k: float) -> tuple:
    """The locked orbit over one period at 1 ms steps, ``(x1_peak, t, x1, y1, x2)`` (read-only arrays): it
    depends on the network only, not on ``x1_apex``, so it is integrated once per network in the process
    (a few tenths of a second each) and every apex of :func:`elevator_descent_rate` reads it."""
    from scipy.integrate import solve_ivp

    from cpgsim.components.yu.converter import _network_rhs

    o = locked_orbit(eps, b, omega, k)
    rhs = _network_rhs((eps,) * 3, (b,) * 3, omega, (k,) * 4)
    s0 = [o.x1_peak, 0.0, o.x2_switch, o.y2_switch, o.x2_switch, o.y2_switch]
    r = solve_ivp(rhs, (0.0, 2 * o.half_period), s0, max_step=1e-3, rtol=1e-10, atol=1e-12)
    arrays = (r.t, r.y[0], r.y[1], r.y[2])
    for a in arrays:
        a.flags.writeable = False
    return (o.x1_peak, *arrays)


class SettableVanDerPolNeuron(VanDerPolNeuron):
    """:class:`~cpgsim.components.neurons.VanDerPolNeuron` plus a state reset: ``set = 1`` puts
    ``(x, y) = (x_set, y_set)`` at the sampled update (used to restart a leg's network on its limit
    cycle after a reflex). Inputs ``set`` (boolean), ``x_set`` (1), ``y_set`` (1/s), default 0.
    ``set`` takes precedence over ``y_reset``.
    """

    def declare(self) -> None:
        super().declare()
        self.add_input("set", unit="1", kind="boolean", default=0.0, description="set (x, y) to (x_set, y_set)")
        self.add_input("x_set", unit="1", default=0.0, description="x after a set")
        self.add_input("y_set", unit="1/s", default=0.0, description="y after a set")

    def define(self, v: Symbols) -> Equations:
        eq = super().define(v)
        s = v.u["set"] > 0.5
        eq.resets = {"x": ca.if_else(s, v.u["x_set"], v.x["x"]),
                     "y": ca.if_else(s, v.u["y_set"], eq.resets.get("y", v.x["y"]))}
        return eq


def _b(expr):
    """SX boolean as 0/1."""
    return ca.if_else(expr, 1, 0)


def _eq(mode, value: int):
    return ca.fabs(mode - value) < 0.5


class YuReflexLogic(Block):
    """Elevator and searching reflex logic of one leg (module docstring).

    Constructor: ``orbit`` (the network's :class:`~cpgsim.components.yu.converter.LockedOrbit`, default
    Table 1) gives the defaults of ``x1_peak``, ``x2_aep``, ``y2_aep``, ``x2_apex``; ``height`` (the
    robot's ``H``, m) the default of ``ground_h = -H``.
    """

    def __init__(self, name: str = "reflex", orbit: LockedOrbit | None = None, height: float = 0.12,
                 omega1: float = TABLE1_OMEGA[0], **params) -> None:
        self.orbit = orbit or locked_orbit()
        self._ground = float(height)
        self._omega1 = float(omega1)
        super().__init__(name, **params)

    def declare(self) -> None:
        o = self.orbit
        self.add_parameter("x1_peak", o.x1_peak, "1", (0, float("inf")), "leader amplitude (AEP state)", strict=True)
        self.add_parameter("x2_aep", o.x2_switch, "1", description="followers at the AEP state (a)")
        self.add_parameter("y2_aep", o.y2_switch, "1/s", description="followers' rate at the AEP state")
        self.add_parameter("x2_apex", o.x2_max, "1", description="followers' maximum (m)")
        self.add_parameter("x1_ob_min", -0.98, "1", (-2, 2), "elevator window: x1 above (no trigger at liftoff)")
        self.add_parameter("x1_ob_max", 0.9, "1", (-2, 2), "elevator window: x1 below (no trigger at touchdown)")
        self.add_parameter("x1_lift", -0.98, "1", (-2, 2), "a swing without contact above this x1 is a lift-off")
        self.add_parameter("x1_td_min", 0.0, "1", (-2, 2), "early touchdown window: x1 above this")
        self.add_parameter("x1_td_max", 0.95, "1", (-2, 2), "early touchdown window: x1 below this")
        self.add_parameter("ground_h", -self._ground, "m", description="nominal ground height from the alpha joint")
        self.add_parameter("x1_apex", o.x1_at_max, "1", (-2, 2),
                           "elevator forward stroke: followers held at their maximum until x1/A passes this")
        self.add_parameter("rate_descent", 1.0, "1", (0, float("inf")),
                           "elevator forward stroke: follower time scale after x1_apex", strict=True)
        self.add_parameter("omega1", self._omega1, "rad/s", (0, float("inf")), "leader natural frequency",
                           strict=True)
        self.add_parameter("early_h_min", 0.01, "m", (0, float("inf")),
                           "early touchdown only with the foot this far above the nominal ground")
        self.add_parameter("elevator", 1.0, "1", (0, 1), "enable the elevator reflex", kind="boolean")
        self.add_parameter("searching", 1.0, "1", (0, 1), "enable the searching reflex", kind="boolean")
        self.add_parameter("early_td", 1.0, "1", (0, 1), "end a swing at an early touchdown", kind="boolean")
        self.add_parameter("found_support", 0.0, "1", (0, 1), "a search ends only on a supporting contact",
                           kind="boolean")
        self.add_parameter("ob_support_veto", 0.0, "1", (0, 1), "no elevator trigger on a supporting contact",
                           kind="boolean")
        self.add_parameter("ob_after_liftoff", 0.0, "1", (0, 1), "elevator only once the foot has left the ground",
                           kind="boolean")
        self.add_parameter("ob_clear_time", 0.0, "s", (0, float("inf")),
                           "with ob_after_liftoff: elevator only once the touchdown flag has been off this long")
        self.add_parameter("withdraw", 0.0, "1", (0, 1), "after a failed search, step back onto the stance line",
                           kind="boolean")
        self.add_parameter("T_return", 0.5, "s", (0, float("inf")), "return time (as the converter's T_return)")
        self.add_parameter("withdraw_timeout", 2.0, "s", (0, float("inf")), "withdraw: longest wait for touchdown")
        self.add_parameter("search_scale1", 0.5, "1", (0, float("inf")), "leader omega scale when searching (Y12)",
                           strict=True)
        self.add_parameter("search_scale23", 1.5, "1", (0, float("inf")), "follower omega scale when searching (Y12)",
                           strict=True)
        self.add_input("x1", unit="1", description="leader output")
        self.add_input("y1", unit="1/s", description="leader rate")
        self.add_input("lambda_ob", unit="1", description="obstacle flag (Y8)")
        self.add_input("lambda_td", unit="1", description="touchdown flag (Y9)")
        self.add_input("rate", unit="1", default=1.0, description="clock rate from the FSM (0 holds the leg)")
        self.add_input("foot_h", unit="m", default=0.0, description="foot height from the alpha joint (FK of q)")
        self.add_input("support", unit="1", default=1.0, description="foothold-like contact (sensory neurons)")
        self.add_input("aim_h", unit="m", default=0.0,
                       description="height of the aimed foothold above the nominal ground (converter)")
        self.add_discrete_state("mode", float(NOMINAL), description="reflex mode 0..4")
        self.add_discrete_state("half_prev", 0.0, description="leader protracting at the last sample")
        self.add_discrete_state("ob_prev", 0.0, description="gated obstacle flag at the last sample")
        self.add_discrete_state("td_prev", 1.0, description="touchdown-with-support flag at the last sample")
        self.add_discrete_state("gaveup", 0.0, description="1 after a failed search until touchdown/next swing end")
        self.add_discrete_state("landed", 0.0, description="touched down since the last swing ended")
        self.add_discrete_state("t_ground", 0.0, "s", "last time the touchdown flag was on")
        self.add_discrete_state("t_mode", 0.0, "s", "time of the last mode change")
        self.add_discrete_state("withdrawn", 0.0, description="1 once the leg withdrew after its give-up")
        for c in ("n_ert", "n_srt", "n_found", "n_early", "n_giveup", "n_withdraw"):
            self.add_discrete_state(c, 0.0, description=f"event counter {c[2:]}")
        outs = [
            ("lead_gain", "1", "leader coupling gain (0: Y13)"), ("omega_scale1", "1", "leader omega scale (Y12)"),
            ("omega_scale23", "1", "follower omega scale (Y12)"), ("rate1", "1", "leader time scale"),
            ("rate23", "1", "follower time scale"), ("x1_set", "1", "leader x after a set"),
            ("y1_set", "1/s", "leader y after a set"), ("x23_set", "1", "followers' x after a set"),
            ("y23_set", "1/s", "followers' y after a set"), ("mode_cmd", "1", "converter mode (this sample's events)"),
            ("mode", "1", "reflex mode (committed state)"),
            ("capture", "1", "store the touchdown offset"), ("swing", "1", "1 while the leg swings"),
            ("active", "1", "1 while a reflex runs"),
            ("reflex", "1", "0 none, 1 elevator, 2 searching, 3 return, 4 withdraw"),
            ("gaveup", "1", "failed search, waiting"),
            ("landed", "1", "touched down since the last swing ended (latched)"),
        ]
        for name, unit, desc in outs:
            self.add_output(name, unit=unit, description=desc)
        for name, desc in (("y1_reset", "Y10 leader reversal"), ("set1", "set the leader state"),
                           ("set23", "set the followers' state")):
            self.add_output(name, unit="1", kind="boolean", description=desc)
        for c in ("n_ert", "n_srt", "n_found", "n_early", "n_giveup", "n_withdraw"):
            self.add_output(c, unit="1", description=f"number of {c[2:]} events so far")

    def define(self, v: Symbols) -> Equations:
        p, u, z = v.p, v.u, v.z
        x1, y1, lob, ltd = u["x1"], u["y1"], u["lambda_ob"] > 0.5, u["lambda_td"] > 0.5
        mode = z["mode"]
        m0, m1, m2, m3, m4, m5 = (_eq(mode, k) for k in (NOMINAL, ELEV_RETRACT, ELEV_FORWARD, SEARCHING, RETURNING,
                                                          WITHDRAW))
        # withdraw after a failed search (module docstring)
        wpending = ca.logic_and(p["withdraw"] > 0.5, z["withdrawn"] < 0.5)
        m4h = ca.logic_and(m4, wpending)  # returning, held: the FSM waits
        since = v.t - z["t_mode"]
        half = swing_half(x1, y1)
        half_prev = z["half_prev"] > 0.5
        running = u["rate"] > 0
        fell = ca.logic_and(half_prev, ca.logic_not(half))
        rose = ca.logic_and(ca.logic_not(half_prev), half)

        airborne = ca.logic_and(z["landed"] < 0.5, v.t - z["t_ground"] >= p["ob_clear_time"])
        not_foothold = ca.logic_and(ca.logic_or(p["ob_support_veto"] < 0.5, u["support"] < 0.5),
                                    ca.logic_or(p["ob_after_liftoff"] < 0.5, airborne))
        ob_gate = ca.logic_and(ca.logic_and(ca.logic_and(m0, half), ca.logic_and(running, lob)),
                               ca.logic_and(ca.logic_and(x1 > p["x1_ob_min"], x1 < p["x1_ob_max"]),
                                            ca.logic_and(p["elevator"] > 0.5, not_foothold)))
        ert = ca.logic_and(ob_gate, z["ob_prev"] < 0.5)
        td_sup = ca.logic_and(ltd, u["support"] > 0.5)
        td_edge = ca.logic_and(td_sup, z["td_prev"] < 0.5)
        high = u["foot_h"] > p["ground_h"] + u["aim_h"] + p["early_h_min"]
        # leader normalised by its amplitude (Y10 changes it: up to 1.23 after an elevator trigger)
        x1n = x1 / ca.fmax(ca.sqrt(x1 * x1 + (y1 / p["omega1"]) ** 2), 1e-9)
        window = ca.logic_and(x1n > p["x1_td_min"], ca.logic_or(x1n < p["x1_td_max"], m2))
        early = ca.logic_and(ca.logic_and(p["early_td"] > 0.5, running),
                             ca.logic_and(ca.logic_and(ca.logic_and(td_edge, high), window),
                                          ca.logic_or(ca.logic_and(m0, half), m2)))
        e1_end = ca.logic_and(m1, y1 > 0)
        e2_end = ca.logic_and(ca.logic_and(m2, y1 <= 0), ca.logic_and(x1 > 0, ca.logic_not(early)))
        nat_end = ca.logic_and(m0, fell)
        srt = ca.logic_and(ca.logic_and(ca.logic_or(nat_end, e2_end), ca.logic_not(ltd)), p["searching"] > 0.5)
        found = ca.logic_and(ca.logic_and(m3, ltd), ca.logic_or(u["support"] > 0.5, p["found_support"] < 0.5))
        giveup = ca.logic_and(ca.logic_and(m3, fell), ca.logic_not(found))
        ret_end = ca.logic_and(m4, rose)
        wfound = ca.logic_and(ca.logic_or(m4h, m5), td_sup)  # a foothold while held / withdrawing
        w_start = ca.logic_and(ca.logic_and(m4h, since >= p["T_return"]), ca.logic_not(wfound))
        w_fail = ca.logic_and(ca.logic_and(m5, since >= p["withdraw_timeout"]), ca.logic_not(wfound))
        found = ca.logic_or(found, wfound)
        to_aep = ca.logic_or(ca.logic_or(e2_end, early), ca.logic_or(found, giveup))

        new_mode = ca.if_else(ert, ELEV_RETRACT,
                   ca.if_else(e1_end, ELEV_FORWARD,
                   ca.if_else(srt, SEARCHING,
                   ca.if_else(ca.logic_or(ca.logic_or(e2_end, early), ca.logic_or(found, ret_end)), NOMINAL,
                   ca.if_else(ca.logic_or(giveup, w_fail), RETURNING,
                   ca.if_else(w_start, WITHDRAW, mode))))))
        n0, n12 = _eq(new_mode, NOMINAL), ca.logic_or(_eq(new_mode, ELEV_RETRACT), _eq(new_mode, ELEV_FORWARD))
        n4 = _eq(new_mode, RETURNING)
        swing_now = ca.logic_or(n12, ca.logic_and(ca.logic_or(n0, n4), ca.logic_and(half, ca.logic_not(to_aep))))
        active = ca.logic_or(ca.logic_or(ca.logic_or(m1, m2), m3), ca.logic_or(m4h, m5))  # from the state
        gaveup = ca.if_else(giveup, 1,
                            ca.if_else(ca.logic_or(ltd, ca.logic_or(ca.logic_or(nat_end, e2_end), early)), 0,
                                       z["gaveup"]))
        # network commands from the mode state (constant over the step's integration)
        lead = _b(ca.logic_or(m0, m4))
        os1 = ca.if_else(m3, p["search_scale1"], 1)
        os23 = ca.if_else(m3, p["search_scale23"], 1)
        frozen = ca.logic_or(m4h, m5)  # withdraw: the network waits on its AEP state
        rate1 = u["rate"] * ca.if_else(frozen, 0, 1)
        rate23 = u["rate"] * ca.if_else(ca.logic_or(m1, frozen), 0,
                                        ca.if_else(m2, ca.if_else(x1n < p["x1_apex"], 0, p["rate_descent"]), 1))
        set23 = ca.logic_or(to_aep, e1_end)
        outputs = {
            "lead_gain": lead, "omega_scale1": os1, "omega_scale23": os23, "rate1": rate1, "rate23": rate23,
            "y1_reset": _b(ert), "set1": _b(to_aep), "x1_set": p["x1_peak"], "y1_set": 0,
            "set23": _b(set23), "x23_set": ca.if_else(e1_end, p["x2_apex"], p["x2_aep"]),
            "y23_set": ca.if_else(e1_end, 0, p["y2_aep"]),
            "mode_cmd": new_mode, "mode": mode, "capture": _b(ca.logic_or(early, found)), "swing": _b(swing_now),
            "active": _b(active),
            "reflex": ca.if_else(ca.logic_or(m1, m2), 1, ca.if_else(m3, 2, ca.if_else(m4, 3, ca.if_else(m5, 4, 0)))),
            "gaveup": z["gaveup"], "landed": z["landed"],
        }
        counters = {"n_ert": ert, "n_srt": srt, "n_found": found, "n_early": early, "n_giveup": giveup,
                    "n_withdraw": w_start}
        m04 = ca.logic_or(m0, m4)
        lifted = ca.logic_and(half, x1 > p["x1_lift"])  # swinging, past the PEP (not waiting on it)
        landed = ca.if_else(ca.logic_or(early, found), 1,
                 ca.if_else(ca.logic_and(ca.logic_not(ltd), ca.logic_or(lifted, ca.logic_not(m04))), 0,
                 ca.if_else(ca.logic_and(ca.logic_and(ltd, ca.logic_not(half)), m04), 1, z["landed"])))
        updates = {
            "mode": new_mode,
            "half_prev": ca.if_else(to_aep, 0, _b(half)),
            "ob_prev": _b(ob_gate),
            "td_prev": _b(td_sup),
            "gaveup": gaveup,
            "t_mode": ca.if_else(ca.fabs(new_mode - mode) > 0.5, v.t, z["t_mode"]),
            "withdrawn": ca.if_else(w_start, 1, ca.if_else(_eq(new_mode, NOMINAL), 0, z["withdrawn"])),
            "landed": landed,
            "t_ground": ca.if_else(ltd, v.t, z["t_ground"]),
        }
        for c, ev in counters.items():
            updates[c] = z[c] + _b(ev)
            outputs[c] = z[c] + _b(ev)
        return Equations(outputs=outputs, updates=updates)
