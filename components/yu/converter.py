"""Yu linear converter (Y6) with its elevator (Y11) and searching (Y14, Y15) modes.

Nominal mode (Yu 2019, eq. 6)::

    alpha = g_a*x1 + h_a
    beta  = g_b*x2 + h_b        (swing set while the leader protracts, stance set otherwise)
    gamma = g_g*x3 + h_g

The leg is in swing while ``y1 > 0`` (and, at ``y1 == 0`` exactly, when ``x1 < 0``: the leader is
at its PEP extreme about to protract; both sets give the same angles there).

**Where the coefficients come from.** :func:`converter_coefficients` computes them from a
:class:`~cpgsim.components.geometry.RobotGeometry` by inverse kinematics (``leg_ik_plane``) at the
geometry's nominal points, on the *real* locked waveforms of the Y5 network rather than on
idealised cosines: :func:`locked_orbit` computes the network's periodic orbit (leader limit
cycle and the followers' fixed point over one half period, by shooting). Measured on Table 1:

- the leader amplitude is ``x1_peak = 1.000033``; ``g_a = alpha_max / x1_peak``, ``h_a = 0``;
- at both swing/stance switches (``y1 = 0``) the followers are at ``x2 = x3 = a = -1.000296``
  (their minimum, -1.000345, follows 5 ms later): the AEP *and* the PEP are matched at ``a``,
  so beta and gamma are continuous at every swing/stance switch (both sets give the AEP/PEP
  angles there);
- the followers' maximum ``m = 0.999292`` comes at ``x1 = -0.035`` in swing and ``+0.035`` in
  stance: the swing set maps ``m`` to the swing apex, the stance set maps ``m`` to the stance
  midpoint.

The apex angles are placed so that the *highest* point of the swing (over the joint-space path
``x2 in [a, m]``) is exactly ``-H + h_max``; the stance path between AEP, midpoint and PEP is
the straight joint-space segment, so the stance foot deviates from the ground line by a few
tenths of a millimetre (YU_SIM), as Yu's linear converter implies.

**Modes** (input ``mode``, set by :class:`~cpgsim.components.yu.reflexes.YuReflexLogic`):

====== ================== ==================================================================
mode   name               joint targets
====== ================== ==================================================================
0      nominal            Y6 + the held touchdown offset ``d`` (see below)
1      elevator, retract  alpha: leader, normalised; beta, gamma: ramp to the new apex angles
2      elevator, forward  alpha: leader, normalised; beta, gamma: new swing set (Y11)
3      searching          Y14 with ``mu`` of Y15, around the angles held at the trigger
4      return             ramp from the angles held at the give-up back to Y6 (the AEP)
5      withdraw           step back from the AEP onto the stance line (see below)
====== ================== ==================================================================

Whenever the mode changes (1 and 2 count as one), the block holds its last output ``q_hold``
and the time ``t_hold`` and blends ``q = (1 - rho)*q_hold + rho*q_mode`` with
``rho = min(1, (t - t_hold)/T)`` -- Yu Y11's ramp ``min(1, (t - t_ob)/T_s)`` -- so joint targets
never jump (``T`` is ``T_s`` for the elevator, ``T_search`` for searching, ``T_return`` for the
return, 0 for nominal).

*Withdraw* (mode 5, only if the reflex logic's ``withdraw`` is on; a choice for Yu's "waiting for
high-level regulation" after a failed search). The foot, back on its AEP over a hole, steps back
onto the stance line: with ``rho = min(1, (t - t_hold)/T_withdraw)``, ``s = min(1, rho/0.7)``,
``d = max(0, (rho - 0.7)/0.3)``, the foot ``f`` goes horizontally from ``FK(q_hold)`` to ``f_w`` with
``s`` (lifted by ``withdraw_lift sin(pi s)``) and then straight down with ``d``; ``q = IK(f)``;
``f_w = (W, W tan(withdraw_alpha), -H - withdraw_dip)`` (``W`` the stance width, ``H`` the standing
height: a point of the stance line, ``withdraw_dip`` below the nominal ground so the foot meets the
ground it left; the vertical end keeps the touchdown force upright, a foot still moving back when
it met the ground read more than the ``support`` cone allows).

*Elevator (Y10, Y11), interpretation.* Y11 ramps the swing coefficients from the nominal to the
raised set within ``T_s`` while the network keeps running. Simulated literally (followers not
touched), the swing that follows the Y10 reversal ends with ``x2`` at 0.2 to 0.7 instead of
``a`` (measured for triggers at 0.3/0.5/0.7/0.9 s): the weakly coupled followers (k = 0.1) need
about 10 s to re-lock to the reversed leader, so the foot does not land on the AEP. Here the
reflex logic freezes the followers during the retraction (mode 1) while beta and gamma ramp
from the held angles to the raised apex angles (retract *and* lift), restarts them at their
maximum ``m`` when the leader turns forward again, and runs them at half speed during the
forward stroke (mode 2: ``x2`` goes ``m -> a`` once while the leader goes from its new PEP to
its new AEP), so the raised swing set (Y11's increments, from IK at clearance
``h_max_new``) puts the foot down on the AEP. In coefficient form this is Y11's ramp from
``(g, h) = (0, angle at t_ob)`` to the raised set. The Y10 reset ``y1 = -1`` changes the
leader's amplitude (to ``sqrt(x1^2 + 1/omega1^2)``, 0.90..1.23 for Yu's triggers), so in the
elevator modes ``alpha = alpha_max * x1 / A`` with ``A = sqrt(x1^2 + (y1/omega1)^2)``
(exactly ``alpha_max`` when the swing ends at ``y1 = 0``), clamped to ``[-alpha_max,
alpha_max]``; during the ramp alpha blends from the nominal map continued from ``t_ob``.

*Searching (Yu 2019, eqs. 14, 15)*, with ``alpha0, beta0, gamma0`` held at the trigger::

    alpha = -da*x1 + alpha0 + da
    beta  = -mu*db*x2 + beta0 - db,   gamma = -mu*dg*x3 + gamma0 - dg
    mu    = 0.5*(sigma - 1)*x1 + 0.5*(sigma + 1)        (mu in [1, sigma])

At the trigger ``x2 = a = -1`` so Y14 starts ``(sigma - 1)*db`` above the held angle: the
``T_search`` blend (0.1 s) removes that step. Y14 protracts alpha up to ``alpha0 + 2*da``, beyond
the nominal ``alpha_max`` bound (the paper's equation is kept as is).

*Touchdown offset.* When a swing ends by touchdown before its nominal end (early touchdown, or
touchdown during a search), the reflex logic jumps the network to the AEP state and pulses
``capture``: the block stores the foot's displacement from the nominal AEP, ``d = FK(q) -
FK(q_AEP)`` (outward, forward, up; m), and for the whole stance outputs ``q = IK(FK(Y6) + d)``:
the foot follows the nominal stance path shifted by ``d``. During the next swing the shift fades
linearly with the leader (``fade = (x1_peak - x1)/(2*x1_peak)``), so the swing ends on the
nominal AEP again (Yu 6.1.2: "can be corrected in the next swing"). ``FK``/``IK`` are the leg's
kinematics (knee up, as :func:`~cpgsim.components.geometry.leg_ik`); with ``d = 0`` the output is Y6.
The shift is Cartesian, not a joint-angle offset (the first version added ``q - q_AEP`` to the
angles): all feet of a tripod then move exactly alike relative to the body. With a joint offset
the shifted foot's path bent away from the others' by a few mm over a stance; the servos
(about 10 N per mm at the foot) turned that into horizontal forces above the 10 N obstacle
threshold, which fired elevator reflexes at lift-off on the DART robot.

*Height memory* (parameter ``height_memory``, default 0 = Yu's behaviour above). Walking on a
raised surface (Yu 6.1.1: the right legs on the 40 mm step), every later swing of Yu's converter
aims at the nominal foothold 40 mm *below* the surface: the foot meets the surface at the swing's
apex (``x1 ~ 0``), the early touchdown freezes it there and the captured forward shift (about
half a stride back) moves the following PEP far behind the nominal one -- every cycle (measured
on the DART robot; the body then pitched and yawed and the left legs touched down early too).
With ``height_memory = 1`` a capture also remembers the foothold's height above the nominal
ground, ``dh = d_up``, if ``aim_min <= dh`` (only footholds found clearly higher: a lower one,
found by searching, is a hole the next swing steps out of; a few mm up is the body's sag or
tilt, and remembering it let the body sink step by step on the DART robot), clamped to
``aim_max``. The next swing fades from ``d`` to ``a = (0, 0, dh)`` instead of to 0, so it lifts
``h_max`` above the remembered surface and lands on the nominal AEP point raised by ``dh``; a
swing that ends normally keeps ``a`` as the stance shift. Any reflex mode clears ``d`` and ``a``
(the elevator and the search aim at the nominal ground; a search holds the posture it starts
from). Output ``aim_h`` (= ``dh``) lets the reflex logic gate early touchdowns relative to the
remembered surface.

| port | dir | shape | unit | meaning |
|---|---|---|---|---|
| ``x1``, ``x2``, ``x3`` | in | 1 | 1 | neuron outputs |
| ``y1`` | in | 1 | 1/s | leader rate (swing/stance selection, amplitude) |
| ``mode`` | in | 1 | 1 | mode command with this sample's events (table above) |
| ``capture`` | in | 1 | 1 | 1: store the touchdown offset now |
| ``q`` | out | 3 | rad | ``(alpha, beta, gamma)`` joint targets |
| ``swing`` | out | 1 | 1 | 1 while the nominal map uses the swing set |
| ``aim_h`` | out | 1 | m | remembered foothold height above the nominal ground (height memory) |

The ``mode`` input only decides the sampled update (hold, offset); the output uses the committed
mode (the state ``mode_prev``), so a recorded or exported output never shows an event before the
reflex logic has committed it.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import casadi as ca
import numpy as np

from cpgsim.components.core import Block, Equations, ParameterError, Symbols
from cpgsim.components.geometry import YU_SIM, RobotGeometry, leg_ik_plane
from cpgsim.components.memo import disk_memo
from cpgsim.components.networks import TABLE1_OMEGA

NOMINAL, ELEV_RETRACT, ELEV_FORWARD, SEARCHING, RETURNING, WITHDRAW = 0, 1, 2, 3, 4, 5
MODE_NAMES = {NOMINAL: "nominal", ELEV_RETRACT: "elevator-retract", ELEV_FORWARD: "elevator-forward",
              SEARCHING: "searching", RETURNING: "return", WITHDRAW: "withdraw"}


# -- the locked network orbit ----------------------------------------------------------------------

@dataclass(frozen=True)
class LockedOrbit:
    """The Y5 network's periodic orbit, seen at the swing/stance switches.

    ``x1_peak``: leader amplitude; ``x2_switch``/``y2_switch``: follower state when the leader
    is at its AEP (``x1 = x1_peak, y1 = 0``; by symmetry also at the PEP); ``x2_max``: the
    followers' maximum and ``x1_at_max`` the leader there (in swing); ``x2_min`` their minimum;
    ``half_period``: time from PEP to AEP.
    """

    x1_peak: float
    x2_switch: float
    y2_switch: float
    x2_max: float
    x2_min: float
    x1_at_max: float
    half_period: float


def _network_rhs(eps: Sequence[float], b: Sequence[float], w: Sequence[float], k: Sequence[float]):
    k12, k13, k23, k32 = k

    def rhs(t, s):
        x1, y1, x2, y2, x3, y3 = s
        st = -4.0 * x1 * y1
        return [y1, -eps[0] * (b[0] * x1 * x1 - 1) * y1 - w[0] ** 2 * x1,
                y2, -eps[1] * (b[1] * x2 * x2 - 1) * y2 - w[1] ** 2 * x2 + k12 * (st - y2) + k32 * (y3 - y2),
                y3, -eps[2] * (b[2] * x3 * x3 - 1) * y3 - w[2] ** 2 * x3 + k13 * (st - y3) + k23 * (y2 - y3)]
    return rhs


def _followers_fixed_point(half_map: Callable[[np.ndarray], np.ndarray], start: np.ndarray,
                           tol: float = 1e-9, warm: int = 8, max_newton: int = 25) -> np.ndarray:
    """The followers' state ``f`` with ``half_map(f) = f`` (their lock to the leader, Yu Y5).

    ``half_map`` takes the followers' state at the leader's PEP to their state at its next AEP (the
    followers run at twice the leader's frequency and their forcing ``-4 x1 y1`` is even in the leader, so
    this is their return map). A few forward iterations of the map (the dynamics themselves, which
    contract onto the lock) bring the start into Newton's basin; then damped Newton on
    ``half_map(f) - f`` with a finite-difference Jacobian, stopped on the residual (``tol``, above the
    integrator's noise of about 1e-11) rather than on a step size below that noise: a solver stopped by
    its own step test ("not making good progress", scipy's ``fsolve`` at b = 9) had found the lock to
    1e-10 and reported failure. Raises :class:`ParameterError` when no lock is found.
    """
    f = np.asarray(start, dtype=float)
    for _ in range(warm):
        f = np.asarray(half_map(f), dtype=float)
        if not np.all(np.isfinite(f)):
            raise ParameterError("network orbit: the followers diverge (no lock to the leader)")
    g = half_map(f) - f
    for _ in range(max_newton):
        res = float(np.max(np.abs(g)))
        if res < tol:
            return f
        jac = np.empty((f.size, f.size))
        for j in range(f.size):
            h = 1e-6 * max(1.0, abs(f[j]))
            e = f.copy()
            e[j] += h
            jac[:, j] = (half_map(e) - e - g) / h
        try:
            step = np.linalg.solve(jac, -g)
        except np.linalg.LinAlgError:
            break
        lam = 1.0
        while lam > 1e-3:
            trial = f + lam * step
            g_trial = half_map(trial) - trial
            if np.all(np.isfinite(g_trial)) and float(np.max(np.abs(g_trial))) < (1.0 - 0.25 * lam) * res:
                break
            lam *= 0.5
        else:
            break
        f, g = trial, g_trial
    res = float(np.max(np.abs(g)))
    if res < tol:
        return f
    raise ParameterError(f"network orbit: the followers do not lock to the leader (return-map residual "
                         f"{res:.1e} after Newton, needs < {tol:.0e})")


def locked_orbit(eps: float = 0.1, b: float = 4.0, omega: tuple[float, float, float] = TABLE1_OMEGA,
                 k: float = 0.1) -> LockedOrbit:
    """Shoot the Y5 network's periodic orbit (leader limit cycle + followers' fixed point).

    About a second of numerical work: memoised in the process and on disk (:mod:`cpgsim.components.memo`).
    """
    return _locked_orbit_disk(float(eps), float(b), tuple(float(w) for w in omega), float(k))


@functools.lru_cache(maxsize=32)
@disk_memo(dataclasses.asdict, lambda d: LockedOrbit(**d))
def _locked_orbit_disk(eps: float, b: float, omega: tuple[float, float, float], k: float) -> LockedOrbit:
    from scipy.integrate import solve_ivp
    from scipy.optimize import brentq

    rhs = _network_rhs((eps,) * 3, (b,) * 3, tuple(omega), (k,) * 4)
    t_max = 3 * math.pi / omega[0]

    def aep(t, s):  # leader at its AEP: y1 crosses zero downward
        return s[1]
    aep.direction, aep.terminal = -1, True

    def half(s0, dense=False):
        r = solve_ivp(rhs, (0.0, t_max), s0, method="DOP853", rtol=1e-11, atol=1e-12, events=aep,
                      dense_output=dense, first_step=1e-3)
        if not r.t_events[0].size:
            raise ParameterError("network orbit: the leader does not oscillate with these parameters")
        return r

    amp0 = 2.0 / math.sqrt(b)
    x1_peak = brentq(lambda a: half([-a, 0, 0, 0, 0, 0]).y_events[0][0][0] - a, 0.5 * amp0, 1.5 * amp0,
                     xtol=1e-12)
    fol = _followers_fixed_point(lambda f: half([-x1_peak, 0.0, *f]).y_events[0][0][2:],
                                 np.array([-amp0, 0.0, -amp0, 0.0]))
    r = half([-x1_peak, 0.0, *fol], dense=True)
    tt = np.linspace(0.0, r.t[-1], 20001)
    s = r.sol(tt)
    i = int(np.argmax(s[2]))
    return LockedOrbit(x1_peak=float(x1_peak), x2_switch=float(fol[0]), y2_switch=float(fol[1]),
                       x2_max=float(s[2][i]), x2_min=float(s[2].min()), x1_at_max=float(s[0][i]),
                       half_period=float(r.t[-1]))


# -- coefficients from the geometry ----------------------------------------------------------------

def leg_height(geometry: RobotGeometry, beta: float | np.ndarray, gamma: float | np.ndarray) -> np.ndarray:
    """Foot height relative to the alpha joint (the leg-plane ``h`` of :mod:`cpgsim.components.geometry`)."""
    leg = geometry.leg
    return leg.thigh * np.sin(beta) + leg.shank * np.sin(np.asarray(beta) - gamma)


@disk_memo(lambda ab: {"beta": float(ab[0]), "gamma": float(ab[1])}, lambda d: (d["beta"], d["gamma"]))
def _apex_angles(geometry: RobotGeometry, end: tuple[float, float], r_apex: float, clearance: float
                 ) -> tuple[float, float]:
    """Apex angles at ``r_apex`` whose joint-space segment from ``end`` peaks at ``-H + clearance``."""
    from scipy.optimize import brentq

    s = np.linspace(0.0, 1.0, 2001)
    target = -geometry.height + clearance

    def peak(h_apex: float) -> float:
        ba, ga = leg_ik_plane(geometry.leg, r_apex, h_apex)
        return float(np.max(leg_height(geometry, end[0] + s * (ba - end[0]), end[1] + s * (ga - end[1]))))

    lo, hi = target - 0.5 * clearance, target
    if peak(hi) <= target + 1e-12:
        return leg_ik_plane(geometry.leg, r_apex, hi)
    h_apex = brentq(lambda h: peak(h) - target, lo, hi, xtol=1e-10)
    return leg_ik_plane(geometry.leg, r_apex, h_apex)


def converter_coefficients(geometry: RobotGeometry = YU_SIM, orbit: LockedOrbit | None = None,
                           clearance_elevator: float | None = None) -> dict[str, float]:
    """Y6 swing/stance sets and the raised (elevator) swing set, as converter parameter values.

    Matching (see the module docstring): ``x1 = +-x1_peak -> alpha = +-alpha_max``;
    ``x2 = a`` (the followers at the switches) -> the AEP/PEP angles; ``x2 = m`` (their maximum)
    -> the apex angles (swing; placed so the path peaks at ``-H + h_max``) or the stance midpoint
    angles (stance). ``clearance_elevator`` (default ``2*h_max``, Yu: 80 mm = 200 % of a 40 mm
    obstacle) gives the raised set.
    """
    orbit = orbit or locked_orbit()
    pts = geometry.nominal_points()
    h_new = 2.0 * geometry.clearance if clearance_elevator is None else float(clearance_elevator)
    if not 0 < h_new < geometry.height + geometry.leg.thigh:
        raise ParameterError(f"clearance_elevator = {h_new} m is not a reachable clearance")
    a, m = orbit.x2_switch, orbit.x2_max
    end = leg_ik_plane(geometry.leg, *pts["AEP"])
    mid = leg_ik_plane(geometry.leg, *pts["stance_mid"])
    r_apex = pts["swing_apex"][0]
    apex = _apex_angles(geometry, end, r_apex, geometry.clearance)
    apex_el = _apex_angles(geometry, end, r_apex, h_new)
    out = {"g_alpha": geometry.alpha_max / orbit.x1_peak, "h_alpha": 0.0}

    def line(name: str, at_m: tuple[float, float]) -> None:
        for j, joint in enumerate(("beta", "gamma")):
            g = (at_m[j] - end[j]) / (m - a)
            out[f"g_{joint}_{name}"] = g
            out[f"h_{joint}_{name}"] = end[j] - g * a

    line("sw", apex)
    line("st", mid)
    line("el", apex_el)
    return out


# -- the block ---------------------------------------------------------------------------------------

class YuConverter(Block):
    """Yu linear converter with elevator, searching and return modes (module docstring).

    Constructor: ``geometry`` (default ``YU_SIM``), ``orbit`` (default: Table 1 network),
    ``clearance_elevator`` (m, default ``2*h_max``); the coefficients computed from them are the
    default values of the parameters (tunable, exported), other keyword arguments set parameters.
    """

    def __init__(self, name: str = "converter", geometry: RobotGeometry = YU_SIM, orbit: LockedOrbit | None = None,
                 clearance_elevator: float | None = None, omega1: float = TABLE1_OMEGA[0], **params) -> None:
        if not isinstance(geometry, RobotGeometry):
            raise ParameterError(f"geometry must be a RobotGeometry, got {type(geometry).__name__}")
        self.geometry = geometry
        self.orbit = orbit or locked_orbit()
        self._coef = converter_coefficients(geometry, self.orbit, clearance_elevator)
        self._clearance_el = None if clearance_elevator is None else float(clearance_elevator)
        self._omega1 = float(omega1)
        super().__init__(name, **params)

    def declare(self) -> None:
        c, o, g = self._coef, self.orbit, self.geometry
        self.add_parameter("g_alpha", c["g_alpha"], "rad", description="alpha amplitude (Y6)")
        self.add_parameter("h_alpha", c["h_alpha"], "rad", description="alpha offset (Y6)")
        for st, what in (("sw", "swing"), ("st", "stance"), ("el", "raised swing, elevator (Y11)")):
            for joint in ("beta", "gamma"):
                for kind, text in (("g", "amplitude"), ("h", "offset")):
                    key = f"{kind}_{joint}_{st}"
                    self.add_parameter(key, c[key], "rad", description=f"{joint} {text}, {what}")
        self.add_parameter("alpha_max", g.alpha_max, "rad", (0, math.pi / 2), "alpha bound, AEP angle", strict=True)
        self.add_parameter("x1_peak", o.x1_peak, "1", (0, math.inf), "leader amplitude on its limit cycle",
                           strict=True)
        self.add_parameter("x2_aep", o.x2_switch, "1", description="followers at the swing/stance switches (a)")
        self.add_parameter("x2_apex", o.x2_max, "1", description="followers' maximum (m)")
        self.add_parameter("omega1", self._omega1, "rad/s", (0, math.inf), "leader natural frequency", strict=True)
        self.add_parameter("T_s", 0.5, "s", (0, math.inf), "elevator ramp time (Y11)")
        self.add_parameter("T_search", 0.1, "s", (0, math.inf), "blend into the searching converter")
        self.add_parameter("T_return", 0.5, "s", (0, math.inf), "return to the AEP after a failed search")
        self.add_parameter("d_alpha", math.radians(7.5), "rad", description="searching amplitude (Y14)")
        self.add_parameter("d_beta", math.radians(4.0), "rad", description="searching amplitude (Y14)")
        self.add_parameter("d_gamma", math.radians(2.5), "rad", description="searching amplitude (Y14)")
        self.add_parameter("sigma", 1.2, "1", (1, math.inf), "searching depth ratio (Y15)")
        self.add_parameter("T_withdraw", 1.0, "s", (0, math.inf), "withdraw step duration", strict=True)
        self.add_parameter("withdraw_alpha", g.alpha_max / 5, "rad",
                           description="withdraw point: alpha on the stance line")
        self.add_parameter("withdraw_lift", g.clearance / 2, "m", (0, math.inf), "withdraw step: lift at mid-step")
        self.add_parameter("withdraw_dip", 0.125 * g.clearance, "m", (0, math.inf),
                           "withdraw point below the nominal ground")
        self.add_parameter("stance_w", g.stance_width, "m", (0, math.inf), "stance line distance W", strict=True)
        self.add_parameter("height", g.height, "m", (0, math.inf), "standing height H", strict=True)
        self.add_parameter("height_memory", 0.0, "1", (0, 1), "next swing aims at the last higher foothold",
                           kind="boolean")
        self.add_parameter("aim_min", 0.5 * g.clearance, "m", (0, math.inf),
                           "smallest remembered foothold height (height memory)")
        self.add_parameter("aim_max", 2 * g.clearance if self._clearance_el is None else self._clearance_el, "m",
                           (0, math.inf), "largest remembered foothold height (height memory)")
        for seg in ("coxa", "thigh", "shank"):
            self.add_parameter(seg, getattr(g.leg, seg), "m", (0, math.inf), f"{seg} length (touchdown shift IK)",
                               strict=True)
        self.add_input("x1", unit="1")
        self.add_input("y1", unit="1/s")
        self.add_input("x2", unit="1")
        self.add_input("x3", unit="1")
        self.add_input("mode", unit="1", default=float(NOMINAL), description="converter mode (0..4)")
        self.add_input("capture", unit="1", default=0.0, description="1: store the touchdown offset")
        self.add_discrete_state("mode_prev", float(NOMINAL), description="committed mode (the output uses it)")
        self.add_discrete_state("q_hold", (0.0, 0.0, 0.0), "rad", "angles held at the last mode change")
        self.add_discrete_state("x1_hold", 0.0, "1", "leader at the last mode change")
        self.add_discrete_state("t_hold", -1e9, "s", "time of the last mode change")
        self.add_discrete_state("offset", (0.0, 0.0, 0.0), "m", "touchdown shift d of the foot (out, fwd, up)")
        self.add_discrete_state("aim", (0.0, 0.0, 0.0), "m", "shift the next swing ends with (height memory)")
        self.add_discrete_state("aim_h", 0.0, "m", "remembered foothold height above the nominal ground")
        self.add_discrete_state("half_prev", 0.0, description="swing half at the last step")
        self.add_output("q", 3, "rad", description="joint targets (alpha, beta, gamma)")
        self.add_output("swing", unit="1", description="1 while the swing set is used")
        self.add_output("aim_h", unit="m", description="remembered foothold height above the nominal ground")

    # the mode expressions, reused for the held output at a mode change
    def _targets(self, v: Symbols, mode, q_hold, x1_hold, t_hold, offset, aim):
        p, u = v.p, v.u
        x1, y1, x2, x3 = u["x1"], u["y1"], u["x2"], u["x3"]
        half = swing_half(x1, y1)
        ga, ha = p["g_alpha"], p["h_alpha"]
        alpha6 = ga * x1 + ha
        beta6 = ca.if_else(half, p["g_beta_sw"] * x2 + p["h_beta_sw"], p["g_beta_st"] * x2 + p["h_beta_st"])
        gamma6 = ca.if_else(half, p["g_gamma_sw"] * x3 + p["h_gamma_sw"], p["g_gamma_st"] * x3 + p["h_gamma_st"])
        q6 = ca.vertcat(alpha6, beta6, gamma6)
        fade = ca.if_else(half, ca.fmin(1, ca.fmax(0, (p["x1_peak"] - x1) / (2 * p["x1_peak"]))), 1)
        shift = fade * offset + (1 - fade) * aim
        q_nom = ca.if_else(ca.dot(shift, shift) > 0, _ik3(p, _fk3(p, q6) + shift), q6)

        def ramp(T):
            return ca.if_else(T > 0, ca.fmin(1, ca.fmax(0, (v.t - t_hold) / ca.fmax(T, 1e-12))), 1)

        # elevator
        rho_e = ramp(p["T_s"])
        amp = ca.sqrt(x1**2 + (y1 / p["omega1"]) ** 2)
        alpha_n = ca.fmin(p["alpha_max"], ca.fmax(-p["alpha_max"], p["alpha_max"] * x1 / ca.fmax(amp, 1e-9)))
        alpha_e = ca.fmin(p["alpha_max"], ca.fmax(-p["alpha_max"],
                                                 (1 - rho_e) * (q_hold[0] + ga * (x1 - x1_hold)) + rho_e * alpha_n))
        m = p["x2_apex"]
        apex_b, apex_g = p["g_beta_el"] * m + p["h_beta_el"], p["g_gamma_el"] * m + p["h_gamma_el"]
        tb = ca.if_else(mode < ELEV_FORWARD - 0.5, apex_b, p["g_beta_el"] * x2 + p["h_beta_el"])
        tg = ca.if_else(mode < ELEV_FORWARD - 0.5, apex_g, p["g_gamma_el"] * x3 + p["h_gamma_el"])
        q_el = ca.vertcat(alpha_e, (1 - rho_e) * q_hold[1] + rho_e * tb, (1 - rho_e) * q_hold[2] + rho_e * tg)
        # searching (Y14, Y15)
        mu = 0.5 * (p["sigma"] - 1) * x1 + 0.5 * (p["sigma"] + 1)
        q_y14 = ca.vertcat(-p["d_alpha"] * x1 + q_hold[0] + p["d_alpha"],
                           -mu * p["d_beta"] * x2 + q_hold[1] - p["d_beta"],
                           -mu * p["d_gamma"] * x3 + q_hold[2] - p["d_gamma"])
        rho_s = ramp(p["T_search"])
        q_sr = (1 - rho_s) * q_hold + rho_s * q_y14
        # return to the AEP
        rho_r = ramp(p["T_return"])
        q_ret = (1 - rho_r) * q_hold + rho_r * q6
        # withdraw: step back onto the stance line (Cartesian blend with a lift)
        rho_w = ramp(p["T_withdraw"])
        f_w = ca.vertcat(p["stance_w"], p["stance_w"] * ca.tan(p["withdraw_alpha"]), -p["height"] - p["withdraw_dip"])
        s_h = ca.fmin(1, rho_w / 0.7)  # back over the first 70 %, then straight down onto the ground
        s_v = ca.fmax(0, (rho_w - 0.7) / 0.3)
        f0 = _fk3(p, q_hold)
        f_wd = ca.vertcat((1 - s_h) * f0[0] + s_h * f_w[0], (1 - s_h) * f0[1] + s_h * f_w[1],
                          (1 - s_v) * f0[2] + s_v * f_w[2] + p["withdraw_lift"] * ca.sin(math.pi * s_h))
        q_wd = _ik3(p, f_wd)
        q = ca.if_else(mode < 0.5, q_nom,
                       ca.if_else(mode < 2.5, q_el, ca.if_else(mode < 3.5, q_sr, ca.if_else(mode < 4.5, q_ret, q_wd))))
        return q, half

    def define(self, v: Symbols) -> Equations:
        z, u, p = v.z, v.u, v.p
        mode = u["mode"]
        # the output uses the committed mode (state); the input only decides this sample's update, so
        # recorded/sent outputs never show an event the reflex logic has not committed yet
        # at the sample a swing ends the stance map takes over with the shift the swing ended with (``aim``);
        # the stored touchdown shift is replaced by the update of this very sample, so use ``aim`` already
        # (the first version used the old shift here for one sample: a search or a reflex starting at
        # that sample held that posture -- 18 mm too low after a foothold found in a ditch)
        swing_end = ca.logic_and(z["half_prev"] > 0.5, ca.logic_not(swing_half(u["x1"], u["y1"])))
        shift_now = ca.if_else(swing_end, z["aim"], z["offset"])
        q_prev, half = self._targets(v, z["mode_prev"], z["q_hold"], z["x1_hold"], z["t_hold"], shift_now,
                                     z["aim"])
        family, family_prev = _family(mode), _family(z["mode_prev"])
        change = family != family_prev
        q_aep = ca.vertcat(p["g_alpha"] * p["x1_peak"] + p["h_alpha"],
                           p["g_beta_st"] * p["x2_aep"] + p["h_beta_st"],
                           p["g_gamma_st"] * p["x2_aep"] + p["h_gamma_st"])
        capture = u["capture"] > 0.5
        reflex_start = ca.logic_and(change, mode > 0.5)
        # touchdown shift of the foot from the nominal AEP; height memory: its height part
        d_new = _fk3(p, q_prev) - _fk3(p, q_aep)
        dh = ca.if_else(ca.logic_and(p["height_memory"] > 0.5, d_new[2] >= p["aim_min"]),
                        ca.fmin(p["aim_max"], d_new[2]), 0)
        zero = ca.DM.zeros(3)
        offset = ca.if_else(capture, d_new,
                            ca.if_else(reflex_start, zero, ca.if_else(swing_end, z["aim"], z["offset"])))
        aim = ca.if_else(capture, ca.vertcat(0, 0, dh), ca.if_else(reflex_start, zero, z["aim"]))
        aim_h = ca.if_else(capture, dh, ca.if_else(reflex_start, 0, z["aim_h"]))
        return Equations(
            outputs={"q": q_prev, "swing": ca.if_else(half, 1, 0), "aim_h": z["aim_h"]},
            updates={"mode_prev": mode,
                     "q_hold": ca.if_else(change, q_prev, z["q_hold"]),
                     "x1_hold": ca.if_else(change, u["x1"], z["x1_hold"]),
                     "t_hold": ca.if_else(change, v.t, z["t_hold"]),
                     "offset": offset, "aim": aim, "aim_h": aim_h,
                     "half_prev": ca.if_else(ca.logic_and(half, u["capture"] < 0.5), 1, 0)},
        )


def _fk3(p, q):
    """Foot ``(outward, forward, up)`` from the alpha joint for joint angles ``q`` (SX), as ``leg_fk``."""
    a, b, g = q[0], q[1], q[2]
    r = p["coxa"] + p["thigh"] * ca.cos(b) + p["shank"] * ca.cos(b - g)
    return ca.vertcat(r * ca.cos(a), r * ca.sin(a), p["thigh"] * ca.sin(b) + p["shank"] * ca.sin(b - g))


def _ik3(p, f):
    """Joint angles for the foot ``f = (outward, forward, up)`` (SX version of ``leg_ik``, knee up; the
    reach is clamped so an unreachable point gives the nearest stretched/folded posture, not NaN)."""
    r = ca.sqrt(f[0] ** 2 + f[1] ** 2)
    dx, h = r - p["coxa"], f[2]
    c = (dx * dx + h * h - p["thigh"] ** 2 - p["shank"] ** 2) / (2 * p["thigh"] * p["shank"])
    gamma = ca.acos(ca.fmin(1, ca.fmax(-1, c)))
    beta = ca.atan2(h, dx) + ca.atan2(p["shank"] * ca.sin(gamma), p["thigh"] + p["shank"] * ca.cos(gamma))
    return ca.vertcat(ca.atan2(f[1], f[0]), beta, gamma)


def swing_half(x1, y1):
    """SX boolean: the leader protracts (``y1 > 0``, or ``y1 == 0`` at its PEP extreme ``x1 < 0``)."""
    return ca.logic_or(y1 > 0, ca.logic_and(y1 == 0, x1 < 0))


def _family(mode):
    """Mode family: 0 nominal, 1 elevator (modes 1, 2), 3 searching, 4 return, 5 withdraw."""
    return ca.if_else(ca.logic_and(mode > 0.5, mode < 2.5), 1, ca.floor(mode + 0.5))
