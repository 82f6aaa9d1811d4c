"""Yu gait FSM for six legs (Sec. 5.2, Table 2, Fig. 12; Y16 gaits), acting as a "virtual clock".

Each leg has a state ``Swing`` (0), ``Stance`` (1), ``SwingProlong`` (2) or ``StanceProlong`` (3).
The FSM acts through each leg's network time scale ``rate`` (the neurons' ``rate`` input):
``Swing``/``Stance`` run the leg's clock, the Prolong states freeze it (``rate = 0``: the leg holds
its posture), a leg running a reflex always runs.

**Gaits (Y16).** The cycle is divided into ``gamma`` slots (2 tripod, 3 tetrapod, 6 wave); in slot
``k`` the legs with ``slot(i) == k`` swing, the others stand. The leader runs at
``gamma*pi/T_g`` in swing and ``gamma*pi/((gamma - 1)*T_g)`` in stance (Y16), implemented as the
time scale ``rate = (omega_Y16 / omega1)`` of the whole network (``omega1 = 2*pi/T_net``), which
changes the frequency without changing the Van der Pol waveform (``eps/omega``), so the
converter's matching stays exact. A stance lasts ``gamma - 1`` slots; in slot ``k`` a standing
leg runs its clock to the fraction ``(j + 1)/(gamma - 1)`` of its stance, ``j = (k - slot(i) - 1)
mod gamma``. The progress is the network time the leg has run since its stance began divided by
the network's half period ``T_half`` (a discrete state per leg, ``tau += rate*(t - t_prev)``): the
leader's ``x1`` is not a cosine (its zero crossing is about 40 ms off the middle of the half
cycle), so a progress read from ``x1`` made every tetrapod/wave slot wait that long. The last
part of a stance ends when the leg's leader passes its PEP (its ``swing`` flag rises).
Phase offsets chosen (legs L1, L2, L3, R1, R2, R3 = Yu legs 1-6), swing slot per leg:

========= ======= ===================== =============================================
gait      gamma   slot(L1..L3, R1..R3)  order
========= ======= ===================== =============================================
1 tripod  2       0 1 0 1 0 1           Yu groups A = {1, 3, 5}, B = {2, 4, 6}
2 tetrapod 3      2 1 0 1 0 2           {L3, R2}, {L2, R1}, {L1, R3}: back-to-front on
                                        each side, the two legs of a segment never together
3 wave    6       2 1 0 5 4 3           L3, L2, L1, R3, R2, R1
========= ======= ===================== =============================================

Offsets come from the slot barrier, not from start values: the legs start as Yu's tripod (leaders
``[-1, 0]`` for legs 1, 3, 5 and ``[1, 0]`` for 2, 4, 6), the slot-0 legs are in group A, and in the
first slot a leg ahead of its schedule waits while the others catch up, so ``gait`` is a
parameter (tunable, exported) like any other.

**Table 2 events, as used here.** A leg is *supported* when ``lambda_td`` is 1, or it has touched
down since its last swing ended (``landed``, latched in the leg), or it gave up its search and
waits on its AEP (``gaveup``). The latch is a choice made after the first closed-loop runs on the
DART robot: with the instantaneous ``lambda_td`` of Table 2, a standing leg that the body's tilt
unloads (its force drops below ``Fcz``, e.g. after a leg stepped onto a 40 mm step) kept NATD
true and the FSM waited for ever.

- ERT / SRT (elevator / searching trigger) are detected in the legs
  (:class:`~cpgsim.components.yu.reflexes.YuReflexLogic`); the FSM sees their effect ``active_i``.
  While any leg runs a reflex (``R``), legs in ``Stance`` go to ``StanceProlong`` at once
  (aborted: frozen mid-stance, "enforcing the leg on the ground come into the Prolong state
  until the leg executing local reflex reaches the touchdown state"), and resume when no reflex
  runs any more; the reflexing leg itself keeps running.
- ATD: all six legs supported (Table 2: ``sum(lambda_td) = 6``): every leg has landed since it last
  swung.
- NATD: ``0 < sum(lambda_td) < 6`` (Yu's Table 2 prints ``lambda_ob``
  here, a typo: NATD is about touchdowns); it blocks the
  exchange (not ATD).
- sTD: the leg's own touchdown. It ends a leg's search and, late in a swing (``early_td``), ends
  the swing early (both in the leg); the FSM sees the swing's end.
- aTD_i: at least one leg of another slot touches down (``lambda_td`` or ``landed``; not
  ``gaveup``). A standing leg starts its swing only with aTD (its stance ends when an alien leg
  has touched down).

**Early stance after an aborted stance** (a choice; Yu is silent). A reflex freezes the standing
legs mid-stance; when it ends they resume their stance while the legs that swung with the reflex
leg have long landed and hold their posture in SwingProlong -- with their feet on the ground.
On the DART robot the resumed stance then dragged those three feet along (the two tripods
fought: lateral forces above the 10 N obstacle threshold, the body yawed 4 degrees and a left
leg's elevator reflex fired at its lift-off). So after an abort (latched from the moment a
reflex sends a Stance leg to StanceProlong until the next slot switch), a leg that waits in
SwingProlong, has landed, and sees the standing legs resume (no reflex runs and some leg of
another slot has its stance part still to do) starts its stance at once: all six feet then push
the body alike. It counts as ready for the switch; at the switch it simply stays in Stance, and
it ends its stance (at its PEP) early and waits in StanceProlong for the next switch. Without an
abort (e.g. a plain early touchdown) a landed leg holds in SwingProlong as Yu's FSM says.

**Transitions** (evaluated at every sample):

==================== ================================================== ==================
from                 condition                                          to
==================== ================================================== ==================
Swing                the leg's swing ended (clock, elevator end, sTD)   SwingProlong
Stance               stance fraction of this slot done                  StanceProlong
Stance               R (a reflex runs somewhere)                        StanceProlong
StanceProlong        not done and not R                                 Stance (resume)
SwingProlong         SWITCH                                             Stance
SwingProlong         after an abort: landed, no R, standing legs resume   Stance (early)
StanceProlong        SWITCH, the leg swings in the next slot, aTD       Swing
StanceProlong        SWITCH, otherwise                                  Stance
==================== ================================================== ==================

``SWITCH`` (then ``k -> k + 1 mod gamma``) = every leg is in its Prolong state with its part of
the slot done (swing ended / stance fraction reached; a swinging-slot leg in early stance, or
waiting in StanceProlong after it, counts as done), no reflex runs, ATD, and aTD for the legs that
swing next. So swing/stance changes happen at ATD; legs finishing early hold; a reflex delays the
whole gait and all legs resynchronize when it ends. For the tripod this is Yu's
FSM: a swing that ends holds in SwingProlong, a stance that ends holds in StanceProlong, and the
groups exchange at ATD.

| port | dir | shape | meaning |
|---|---|---|---|
| ``swing``, ``active``, ``landed``, ``gaveup``, ``lambda_td`` | in | 6 | per-leg status |
| ``rate`` | out | 6 | clock time scale per leg |
| ``state`` | out | 6 | 0 Swing, 1 Stance, 2 SwingProlong, 3 StanceProlong |
| ``slot`` | out | 1 | current slot ``k`` |
| ``atd``, ``natd`` | out | 1 | ATD, NATD flags |
| ``atd_alien`` | out | 6 | aTD per leg |
| ``n_switch`` | out | 1 | number of slot switches so far |
"""

from __future__ import annotations

import math

import casadi as ca

from cpgsim.components.core import Block, Equations, ParameterError, Symbols
from cpgsim.components.yu.converter import locked_orbit

SWING, STANCE, SWING_PROLONG, STANCE_PROLONG = 0, 1, 2, 3
STATE_NAMES = ("Swing", "Stance", "SwingProlong", "StanceProlong")
GAITS = {1: ("tripod", 2, (0, 1, 0, 1, 0, 1)),
         2: ("tetrapod", 3, (2, 1, 0, 1, 0, 2)),
         3: ("wave", 6, (2, 1, 0, 5, 4, 3))}
GAIT_IDS = {name: gid for gid, (name, _, _) in GAITS.items()}


def gait_id(gait: int | str) -> int:
    """``1``/``"tripod"``, ``2``/``"tetrapod"``, ``3``/``"wave"`` -> 1, 2, 3."""
    if isinstance(gait, str):
        if gait not in GAIT_IDS:
            raise ParameterError(f"unknown gait {gait!r} (known: {', '.join(GAIT_IDS)})")
        return GAIT_IDS[gait]
    if gait not in GAITS:
        raise ParameterError(f"gait must be 1 (tripod), 2 (tetrapod) or 3 (wave), got {gait!r}")
    return int(gait)


def _select(gait, values):
    """``values[gait - 1]`` for a symbolic gait in 1..3."""
    return ca.if_else(gait < 1.5, values[0], ca.if_else(gait < 2.5, values[1], values[2]))


class YuGaitFSM(Block):
    """Six-leg gait FSM (module docstring). Parameters: ``gait`` (1 tripod, 2 tetrapod, 3 wave),
    ``T_g`` (gait period, s), ``T_net`` (the networks' natural period ``2*pi/omega1``, s),
    ``T_half`` (network half period, PEP to AEP), ``p_tol`` (stance-fraction tolerance)."""

    def __init__(self, name: str = "fsm", gait: int | str = 1, **params) -> None:
        self._gait = gait_id(gait)
        super().__init__(name, **params)

    def declare(self) -> None:
        self.add_parameter("gait", float(self._gait), "1", (1, 3), "1 tripod, 2 tetrapod, 3 wave (Y16)",
                           kind="integer")
        self.add_parameter("T_g", 5.0, "s", (0, math.inf), "gait cycle period (Y16)", strict=True)
        self.add_parameter("T_net", 5.0, "s", (0, math.inf), "network natural period 2*pi/omega1", strict=True)
        self.add_parameter("T_half", locked_orbit().half_period, "s", (0, math.inf),
                           "network time from PEP to AEP", strict=True)
        self.add_parameter("p_tol", 1e-3, "1", (0, 0.5), "stance fraction tolerance")
        for name, desc in (("swing", "1 while the leg swings"), ("active", "1 while the leg runs a reflex"),
                           ("landed", "1: touched down since its last swing"), ("gaveup", "1: failed search, waiting"),
                           ("lambda_td", "touchdown flag")):
            self.add_input(name, 6, "1", description=desc)
        self.add_discrete_state("slot", 0.0, description="current slot k")
        self.add_discrete_state("state", (-1.0,) * 6, description="leg states (-1 before the first sample)")
        self.add_discrete_state("n_switch", 0.0, description="slot switches so far")
        self.add_discrete_state("tau", (0.0,) * 6, "s", "network time run since the stance began")
        self.add_discrete_state("t_prev", 0.0, "s", "time of the last sample")
        self.add_discrete_state("aborted", 0.0, description="a reflex aborted a stance in this slot")
        self.add_output("rate", 6, "1", description="clock time scale per leg")
        self.add_output("state", 6, "1", description="0 Swing, 1 Stance, 2 SwingProlong, 3 StanceProlong")
        self.add_output("slot", unit="1", description="current slot")
        self.add_output("atd", unit="1", description="ATD: all six legs supported")
        self.add_output("natd", unit="1", description="NATD: 0 < sum(lambda_td) < 6")
        self.add_output("atd_alien", 6, "1", description="aTD: a leg of another slot touches down")
        self.add_output("n_switch", unit="1", description="slot switches so far")

    def _rates(self, p, state, active):
        gam = _select(p["gait"], (2, 3, 6))
        speed = p["T_net"] / p["T_g"]
        r_sw, r_st = speed * gam / 2, speed * gam / (2 * (gam - 1))
        out = []
        for i in range(6):
            s = state[i]
            r = ca.if_else(active[i] > 0.5, speed,
                           ca.if_else(ca.fabs(s - SWING) < 0.5, r_sw, ca.if_else(ca.fabs(s - STANCE) < 0.5, r_st, 0)))
            out.append(r)
        return ca.vertcat(*out)

    def define(self, v: Symbols) -> Equations:
        p, u, z = v.p, v.u, v.z
        gait, k = p["gait"], z["slot"]
        gam = _select(gait, (2, 3, 6))
        slot_of = [_select(gait, tuple(GAITS[g][2][i] for g in (1, 2, 3))) for i in range(6)]
        td = [ca.logic_or(u["lambda_td"][i] > 0.5, u["landed"][i] > 0.5) for i in range(6)]
        supp = [ca.logic_or(td[i], u["gaveup"][i] > 0.5) for i in range(6)]
        r_any = ca.sum1(u["active"]) > 0.5
        n_td = sum(_b(u["lambda_td"][i] > 0.5) for i in range(6))
        atd = sum(_b(s) for s in supp) > 5.5
        natd = ca.logic_and(n_td > 0.5, n_td < 5.5)
        k_next = ca.fmod(k + 1, gam)
        a_td, ready, done, role_sw, s_eff = [], [], [], [], []
        for i in range(6):
            a_td.append(sum(_b(ca.logic_and(td[j], ca.fabs(slot_of[j] - slot_of[i]) > 0.5)) for j in range(6)) > 0.5)
            sw = ca.fabs(slot_of[i] - k) < 0.5
            j = ca.fmod(k - slot_of[i] - 1 + 2 * gam, gam)
            target = (j + 1) / (gam - 1)
            prog = z["tau"][i] / p["T_half"]
            # the last part of a stance ends with the stance itself (the leader passes its PEP)
            dn = ca.logic_or(u["swing"][i] > 0.5, ca.logic_and(target < 1 - 1e-9, prog >= target - p["p_tol"]))
            s = ca.if_else(z["state"][i] < -0.5, ca.if_else(sw, SWING, STANCE), z["state"][i])
            role_sw.append(sw)
            done.append(dn)
            s_eff.append(s)
            # a leg of this slot is ready once its swing is over: SwingProlong, an early stance (Stance), or an
            # early stance already ended at its PEP (StanceProlong: it waits there for the switch)
            ready.append(ca.if_else(sw, ca.fabs(s - SWING) > 0.5,
                                    ca.logic_and(ca.fabs(s - STANCE_PROLONG) < 0.5, dn)))
        all_ready = ready[0]
        next_ok = ca.logic_or(ca.fabs(slot_of[0] - k_next) > 0.5, a_td[0])
        for i in range(1, 6):
            all_ready = ca.logic_and(all_ready, ready[i])
            next_ok = ca.logic_and(next_ok, ca.logic_or(ca.fabs(slot_of[i] - k_next) > 0.5, a_td[i]))
        switch = ca.logic_and(ca.logic_and(all_ready, ca.logic_not(r_any)), ca.logic_and(atd, next_ok))
        # early stance after an aborted stance (module docstring)
        in_stance = sum(_b(ca.fabs(s - STANCE) < 0.5) for s in s_eff) > 0.5
        aborted = ca.logic_or(z["aborted"] > 0.5, ca.logic_and(r_any, in_stance))
        standing_left = sum(_b(ca.logic_and(ca.logic_not(role_sw[j]), ca.logic_not(done[j]))) for j in range(6)) > 0.5
        resume = ca.logic_and(ca.logic_and(aborted, ca.logic_not(r_any)), standing_left)
        new_states = []
        for i in range(6):
            s, dn = s_eff[i], done[i]
            swing_next = ca.fabs(slot_of[i] - k_next) < 0.5

            def is_(code, s=s):
                return ca.fabs(s - code) < 0.5
            ns = ca.if_else(is_(SWING), ca.if_else(u["swing"][i] > 0.5, SWING, SWING_PROLONG),
                 ca.if_else(is_(SWING_PROLONG), ca.if_else(ca.logic_or(switch, ca.logic_and(resume, td[i])), STANCE,
                                                           SWING_PROLONG),
                 ca.if_else(is_(STANCE), ca.if_else(ca.logic_or(dn, r_any), STANCE_PROLONG, STANCE),
                            ca.if_else(switch, ca.if_else(swing_next, SWING, STANCE),
                                       ca.if_else(ca.logic_and(ca.logic_not(dn), ca.logic_not(r_any)),
                                                  STANCE, STANCE_PROLONG)))))
            new_states.append(ns)
        state_now = ca.vertcat(*s_eff)
        rate_now = self._rates(p, state_now, u["active"])
        tau = z["tau"] + rate_now * (v.t - z["t_prev"])
        entering = [ca.logic_and(ca.fabs(s_eff[i] - SWING_PROLONG) < 0.5, ca.fabs(new_states[i] - STANCE) < 0.5)
                    for i in range(6)]
        tau = ca.vertcat(*[ca.if_else(entering[i], 0, tau[i]) for i in range(6)])
        return Equations(
            outputs={"rate": rate_now, "state": state_now, "slot": k,
                     "atd": _b(atd), "natd": _b(natd), "atd_alien": ca.vertcat(*[_b(a) for a in a_td]),
                     "n_switch": z["n_switch"]},
            updates={"slot": ca.if_else(switch, k_next, k), "state": ca.vertcat(*new_states),
                     "n_switch": z["n_switch"] + _b(switch), "tau": tau, "t_prev": v.t,
                     "aborted": ca.if_else(switch, 0, _b(aborted))},
        )


def _b(expr):
    return ca.if_else(expr, 1, 0)
