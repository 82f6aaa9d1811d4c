"""Yu sensory neurons SN_ob and SN_td (Yu 2019, eqs. 7-9) with a persistence debounce.

Input: the toe force ``F = (Fx lateral, Fy forward, Fz vertical)`` (N), the ground's force on the
foot (``Fz > 0`` standing)::

    raw_ob = |Fx| > Fcx  or  |Fy| > Fcy        (Y8: a binary OR)
    raw_td = |Fz| > Fcz                        (Y9)

Support (a choice, for the reflex logic's early touchdown and, optionally, the end of a search):
``raw_sup = Fz > Fcz`` and ``sqrt(Fx^2 + Fy^2) < support_ratio * Fz`` -- the ground pushes the
foot up, within ``atan(support_ratio)`` of the vertical (default 0.5: 27 degrees). Y9 uses
``|Fz|``, so a foot sliding down (or up) a step's face reads ``lambda_td = 1`` from the friction
alone; on the DART robot a swing that met the 40 mm step's face while descending was then taken
for an early touchdown on the step (the foot stood against the face and slid off) before the
horizontal force reached ``Fcy``. With friction 1 a contact force can lean 45 degrees on any
surface, and a 45-degree cone still let a foot that met the step's edge at the top of its swing
count as standing on the corner; within 27 degrees such an edge contact keeps pushing until the
obstacle flag (elevator) or a real foothold decides. Footholds measured on the DART robot lean
less than 17 degrees (horizontal/vertical below 0.3). ``support`` tells a foothold from a face.

Debounce (a choice: touchdowns in DART spike to 50-150 N for a sample or two, contact
forces being impulses over the step): a flag ``lambda`` takes the raw value only after the raw value has
differed from it for ``debounce`` seconds (both edges), sampled at the macro step; the time of
the last agreement is a discrete state, so the filter does not depend on the step size.
``debounce = 0`` follows the raw value at once. Default 5 ms (five 1 kHz samples): an impact
spike of one or two samples is ignored, a foot pushing on a step face or standing is not.

| port / state | dir | unit | meaning |
|---|---|---|---|
| ``toe_force`` | in (3) | N | ``(Fx, Fy, Fz)`` |
| ``lambda_ob`` / ``lambda_td`` | out | 1 | debounced flags (0/1), the discrete states |
| ``raw_ob`` / ``raw_td`` | out | 1 | thresholded, not debounced |
| ``support`` / ``raw_sup`` | out | 1 | foothold-like contact (debounced / raw) |

Sensing lag (a study option, off by default): ``tau_f`` (s, >= 0) puts a first-order low-pass on the
toe force that Y8 reads (the obstacle flag; Y9 and support read the force as it is), sampled at the macro
step: ``F_f += (1 - exp(-dt/tau_f)) (F - F_f)`` with ``dt`` the time since the last sample (``F_f = F`` at
the first; a discrete state, so the filter does not depend on the step size); ``tau_f = 0`` (default)
passes the force through unchanged. It models a filtered force sensor (the prototype's "filter-like
threshold", Yu Sec. 6.2) for docs/fidelity.md open item 2. ``force_f`` outputs the filtered force.

Sensing delay (a study option, off by default): ``delay_f`` (s, 0 to 50 ms) makes Y8 read the toe force
of ``k = round(delay_f / dt)`` samples ago, ``dt`` the time since the last sample (the macro step): a
delay line of ``DELAY_SAMPLES`` = 50 past samples and the current one held as the discrete state
``force_hist`` (newest first; before the first sample the force is taken to have been the first
sample's), ``dt`` as the discrete state ``h_f`` (the signals read after the update at the same time
see the same delay). The delayed force then goes through the low-pass (``tau_f``), so ``force_f`` is
the force as Y8 reads it; Y9 and support keep the raw force. ``delay_f = 0`` (default) passes the
force through unchanged; a ``delay_f`` above 50 ms is refused (ParameterError), and at a macro step
below 1 ms ``k`` is cut to 50 samples. A pure transport delay of the sensor, for docs/fidelity.md
open item 2 beside ``tau_f``.

Parameters: ``Fcx``, ``Fcy``, ``Fcz`` (N, >= 0; Yu simulation 10, 10, 2 N, prototype 30 N),
``debounce`` (s, >= 0), ``support_ratio`` (>= 0). ``lambda_td`` and ``support`` start at 1 (standing),
``lambda_ob`` at 0.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import casadi as ca

from cpgsim.components.core import Block, Equations, Symbols

DELAY_SAMPLES = 50  # the delay line's length: 50 ms at 1 ms sampling


def debounced(flag, t_agree, raw, t, debounce):
    """Persistence filter: ``(flag+, t_agree+)`` after a sample of ``raw`` at time ``t``."""
    agree = flag == raw
    switch = ca.logic_and(ca.logic_not(agree), t - t_agree >= debounce - 1e-9)
    new_flag = ca.if_else(switch, raw, flag)
    new_t = ca.if_else(ca.logic_or(agree, switch), t, t_agree)
    return new_flag, new_t


def delay_line(f, line, h_last, t_last, t, delay):
    """Pure delay: ``(f_delayed, line+, h+)`` for the force ``f`` sampled at ``t`` (see the module docstring).

    ``line`` holds the force at the last ``DELAY_SAMPLES + 1`` samples (3 each, newest first), ``t_last``
    the time of the newest (< 0: none yet, the history is then taken to be ``f``), ``h_last`` the sampling
    interval before it (0: unknown). A new sample (``t > t_last``) is pushed in front; evaluated again at
    ``t = t_last`` (the signals after the update) the line is left as it is, so the result is the same.
    The delay in samples is ``k = round(delay / h)``, at most ``DELAY_SAMPLES``; ``k = 0`` returns ``f``.
    """
    n = 3 * DELAY_SAMPLES
    first = t_last < 0
    new = t > t_last + 1e-12
    h = ca.if_else(ca.logic_and(new, ca.logic_not(first)), t - t_last, h_last)
    prev = ca.if_else(first, ca.repmat(f, DELAY_SAMPLES + 1, 1), line)
    line = ca.if_else(new, ca.vertcat(f, prev[:n]), line)  # line[0:3] is f at t
    k = ca.if_else(ca.logic_and(delay > 0, h > 0),
                   ca.fmin(ca.floor(delay / ca.fmax(h, 1e-12) + 0.5), DELAY_SAMPLES), 0)
    out = f
    for i in range(1, DELAY_SAMPLES + 1):
        out = ca.if_else(k == i, line[3 * i:3 * (i + 1)], out)
    return out, line, h


class YuSensoryNeurons(Block):
    """SN_ob and SN_td of Yu Fig. 5 (see the module docstring).

    ``delay_line``: build the sensing delay (the ``delay_f`` parameter and its ``DELAY_SAMPLES``-sample line of
    discrete states). Off by default, and on when ``delay_f`` is given: the line is a select chain over 153
    states per leg that doubled the six-leg controller's step (8.7 -> 16.4 us, docs/performance.md) even at
    ``delay_f = 0``, so a block that is not asked for a delay does not carry it."""

    def __init__(self, name: str, start: Mapping[str, Any] | None = None, delay_line: bool | None = None,
                 **params: Any) -> None:
        self._delay_line = ("delay_f" in params) if delay_line is None else bool(delay_line)
        super().__init__(name, start, **params)

    @property
    def absent_parameters(self) -> dict[str, str]:
        """``delay_f`` when built without the delay line, and how to build it with one (the graph's error for
        a ``*.sensors.delay_f`` that matches nothing says so)."""
        if self._delay_line:
            return {}
        return {"delay_f": "the sensors are built with their delay line: YuSensoryNeurons(delay_line=True), "
                           "hexapod_controller(sensor_delay=True), or a scenario that sets it"}

    def declare(self) -> None:
        self.add_parameter("Fcx", 10.0, "N", (0, math.inf), "lateral obstacle threshold (Y8)")
        self.add_parameter("Fcy", 10.0, "N", (0, math.inf), "forward obstacle threshold (Y8)")
        self.add_parameter("Fcz", 2.0, "N", (0, math.inf), "touchdown threshold (Y9)")
        self.add_parameter("debounce", 0.005, "s", (0, math.inf), "a flag follows the raw value after this long")
        self.add_parameter("support_ratio", 0.5, "1", (0, math.inf),
                           "support: horizontal force below this times the vertical one")
        self.add_parameter("tau_f", 0.0, "s", (0, math.inf), "low-pass time constant on the toe force (0: off)")
        self.add_discrete_state("force_f", (0.0, 0.0, 0.0), "N", "low-passed toe force (tau_f > 0)")
        self.add_discrete_state("t_f", -1.0, "s", "time of the last filter sample (< 0: none yet)")
        if self._delay_line:
            self.add_parameter("delay_f", 0.0, "s", (0, DELAY_SAMPLES * 1e-3),
                               f"pure delay on the toe force Y8 reads (0: off; at most {DELAY_SAMPLES} samples)")
            self.add_discrete_state("force_hist", (0.0,) * (3 * (DELAY_SAMPLES + 1)), "N",
                                    f"toe force at the last {DELAY_SAMPLES + 1} samples, newest first (delay_f > 0)")
            self.add_discrete_state("h_f", 0.0, "s", "sampling interval before the last sample (0: not known yet)")
        self.add_input("toe_force", 3, "N", description="ground force on the foot (Fx lateral, Fy forward, Fz up)")
        self.add_discrete_state("lambda_ob", 0.0, description="debounced obstacle flag")
        self.add_discrete_state("lambda_td", 1.0, description="debounced touchdown flag")
        self.add_discrete_state("t_ob", 0.0, "s", "last time raw_ob agreed with lambda_ob")
        self.add_discrete_state("t_td", 0.0, "s", "last time raw_td agreed with lambda_td")
        self.add_discrete_state("support", 1.0, description="debounced support flag")
        self.add_discrete_state("t_sup", 0.0, "s", "last time raw_sup agreed with support")
        self.add_output("lambda_ob", unit="1", description="elevator trigger signal (Y8), debounced")
        self.add_output("lambda_td", unit="1", description="touchdown signal (Y9), debounced")
        self.add_output("raw_ob", unit="1", description="Y8 without debounce")
        self.add_output("raw_td", unit="1", description="Y9 without debounce")
        self.add_output("support", unit="1", description="foothold-like contact (Fz > Fcz, within 45 deg), debounced")
        self.add_output("raw_sup", unit="1", description="support without debounce")
        self.add_output("force_f", 3, "N",
                        description="toe force as Y8 reads it (delayed if delay_f > 0, low-passed if tau_f > 0)")

    def define(self, v: Symbols) -> Equations:
        f_in, p, z = v.u["toe_force"], v.p, v.z
        delay: dict = {}
        f_d = f_in
        if self._delay_line:
            f_d, delay["force_hist"], delay["h_f"] = delay_line(f_in, z["force_hist"], z["h_f"], z["t_f"], v.t,
                                                                p["delay_f"])
        on = p["tau_f"] > 0
        a = ca.if_else(ca.logic_and(on, z["t_f"] >= 0),
                       1 - ca.exp(-(v.t - z["t_f"]) / ca.fmax(p["tau_f"], 1e-12)), 1)  # first sample: F_f = F
        f = ca.if_else(on, z["force_f"] + a * (f_d - z["force_f"]), f_d)
        raw_ob = ca.if_else(ca.logic_or(ca.fabs(f[0]) > p["Fcx"], ca.fabs(f[1]) > p["Fcy"]), 1, 0)
        raw_td = ca.if_else(ca.fabs(f_in[2]) > p["Fcz"], 1, 0)
        ob, t_ob = debounced(z["lambda_ob"], z["t_ob"], raw_ob, v.t, p["debounce"])
        td, t_td = debounced(z["lambda_td"], z["t_td"], raw_td, v.t, p["debounce"])
        raw_sup = ca.if_else(ca.logic_and(f_in[2] > p["Fcz"],
                                          f_in[0] ** 2 + f_in[1] ** 2 < (p["support_ratio"] * f_in[2]) ** 2),
                             1, 0)
        sup, t_sup = debounced(z["support"], z["t_sup"], raw_sup, v.t, p["debounce"])
        return Equations(
            outputs={"lambda_ob": z["lambda_ob"], "lambda_td": z["lambda_td"], "raw_ob": raw_ob, "raw_td": raw_td,
                     "support": z["support"], "raw_sup": raw_sup, "force_f": f},
            updates={"force_f": f, **delay, "t_f": v.t, "lambda_ob": ob, "t_ob": t_ob,
                     "lambda_td": td, "t_td": t_td, "support": sup, "t_sup": t_sup},
        )
