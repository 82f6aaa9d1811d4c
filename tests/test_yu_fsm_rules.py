"""The gait FSM's rules one by one, on the FSM block alone with scripted leg flags (quick tier: no robot,
no network). Each expected value comes from Yu 2019 (Table 2, Sec. 5.2, Y16) as the module docstring of
:mod:`cpgsim.components.yu.fsm` transcribes it, worked out by hand here:

- legs 0..5 = L1, L2, L3, R1, R2, R3; tripod (gamma 2) slot 0 = {L1, L3, R2} swings, {L2, R1, R3} stands;
- Y16: omega_swing = gamma*pi/T_g, omega_stance = gamma*pi/((gamma - 1)*T_g), and the FSM's ``rate`` is
  omega/omega1 with omega1 = 2*pi/T_net, so rate_swing = gamma*T_net/(2*T_g) and rate_stance =
  gamma*T_net/(2*(gamma - 1)*T_g); a Prolong state freezes the clock (rate 0), a reflexing leg runs at
  T_net/T_g;
- the FSM samples every macro step; row ``k`` of an output shows the FSM after it has seen the inputs
  of sample ``k``.
"""

from __future__ import annotations

import numpy as np
import pytest

from cpgsim.components.yu.fsm import STANCE, STANCE_PROLONG, SWING, SWING_PROLONG, YuGaitFSM
from cpgsim.harness.simulate import simulate

DT = 0.01
A, B = [0, 2, 4], [1, 3, 5]  # tripod slot 0 and slot 1


def run(steps: int, flags, gait: int = 1, **params):
    """The FSM for ``steps`` samples; ``flags(k)`` gives ``{input: 6 values}`` at sample ``k`` (missing inputs
    are 0). Returns ``(state, rate, slot, n_switch, atd, natd, atd_alien)`` as arrays over the samples."""
    names = ("swing", "active", "landed", "gaveup", "lambda_td")
    series = {n: np.zeros((6, steps + 1)) for n in names}
    for k in range(steps + 1):
        for n, v in flags(k).items():
            series[n][:, k] = v
    fsm = YuGaitFSM("fsm", gait=gait, **{"T_g": 5.0, "T_net": 5.0, "T_half": 1.0, **params})
    res = simulate(fsm, t_end=steps * DT, dt=DT, inputs=series, backend="casadi")
    return tuple(res[f"fsm.{o}"] for o in ("state", "rate", "slot", "n_switch", "atd", "natd", "atd_alien"))


def legs(*on: int) -> np.ndarray:
    v = np.zeros(6)
    v[list(on)] = 1.0
    return v


ALL = legs(0, 1, 2, 3, 4, 5)


def test_the_first_sample_starts_slot_0_legs_in_swing_and_the_others_in_stance():
    state, rate, slot, *_ = run(2, lambda k: {"swing": legs(*A)})
    assert list(state[0]) == [SWING, STANCE, SWING, STANCE, SWING, STANCE] and slot[0] == 0


@pytest.mark.parametrize("gait, gamma, first", [(1, 2, A), (2, 3, [2, 4]), (3, 6, [2])])
def test_rates_are_yu_y16_swing_and_stance_frequencies_over_omega1(gait, gamma, first):
    # ``first``: the legs of slot 0 (tripod {L1, L3, R2}; tetrapod {L3, R2}; wave {L3}), by the slot table
    T_g, T_net = 4.0, 5.0
    state, rate, *_ = run(2, lambda k: {"swing": legs(*first)}, gait=gait, T_g=T_g, T_net=T_net)
    rest = [i for i in range(6) if i not in first]
    assert np.all(state[1, first] == SWING) and np.all(state[1, rest] == STANCE)
    assert np.allclose(rate[1, first], gamma * T_net / (2 * T_g), rtol=1e-12)
    assert np.allclose(rate[1, rest], gamma * T_net / (2 * (gamma - 1) * T_g), rtol=1e-12)


def test_a_swing_ends_in_swing_prolong_when_the_legs_swing_flag_falls_and_its_clock_stops():
    # L1 swings until sample 5 (swing flag 1), then its flag falls; the standing legs' leaders stay before PEP
    state, rate, *_ = run(8, lambda k: {"swing": legs(0, 2, 4) if k < 5 else legs(2, 4)})
    assert np.all(state[:5, 0] == SWING) and np.all(state[5:, 0] == SWING_PROLONG) and np.all(rate[5:, 0] == 0.0)
    assert np.all(state[5:, 2] == SWING) and np.all(state[5:][:, B] == STANCE)


def test_a_reflex_sends_every_standing_leg_to_stance_prolong_and_its_end_resumes_them():
    # wave (the reflex rate T_net/T_g differs from the swing rate 6*T_net/(2*T_g)): L3 swings in slot 0 and runs
    # a reflex from sample 3 to 6; the reflexing leg keeps running at T_net/T_g
    state, rate, *_ = run(10, lambda k: {"swing": legs(2), "active": legs(2) if 3 <= k <= 6 else np.zeros(6)},
                          gait=3, T_g=4.0, T_net=5.0)
    wave_a = [i for i in range(6) if i != 2]  # every leg but L3 (slot 0) stands
    assert np.all(state[:3][:, wave_a] == STANCE) and np.all(state[3:7][:, wave_a] == STANCE_PROLONG)
    assert np.all(rate[3:7][:, wave_a] == 0.0) and np.allclose(rate[3:7, 2], 5.0 / 4.0)
    assert np.allclose(rate[:3, 2], 6 * 5.0 / (2 * 4.0)) and np.all(state[:, 2] == SWING)
    assert np.all(state[7:][:, wave_a] == STANCE)  # resumed: their parts are not done and no reflex runs
    assert np.allclose(rate[7:, 1], 6 * 5.0 / (2 * 5 * 4.0))  # back to the wave's stance rate


def test_switch_needs_every_leg_ready_atd_and_no_reflex():
    """Tripod exchange: slot-0 legs ended their swings (SwingProlong), the standing legs' leaders passed PEP
    (their swing flag rose: stance done, StanceProlong), all six supported (ATD): the groups exchange."""
    def flags(k):
        return {"swing": legs(*A) if k < 2 else legs(*B), "lambda_td": ALL}
    state, rate, slot, n_switch, atd, natd, alien = run(6, flags)
    assert np.all(state[2, A] == SWING_PROLONG) and np.all(state[2, B] == STANCE_PROLONG)
    assert atd[2] == 1 and natd[2] == 0 and np.all(alien[2] == 1) and slot[2] == 0
    assert np.all(slot[3:] == 1) and np.all(n_switch[3:] == 1)  # one switch, at the first sample all were ready
    assert np.all(state[3, A] == STANCE) and np.all(state[3, B] == SWING)


@pytest.mark.parametrize("support", ["none", "landed", "gaveup"])
def test_natd_blocks_the_exchange_unless_the_leg_landed_or_gave_up(support):
    """L1 never touches down (lambda_td 0): NATD (0 < sum < 6) holds every leg; a latched touchdown
    (``landed``) or a failed search waiting on its AEP (``gaveup``) counts as support (Table 2 as used here)."""
    extra = {"landed": legs(0)} if support == "landed" else {"gaveup": legs(0)} if support == "gaveup" else {}

    def flags(k):
        return {"swing": legs(*A) if k < 2 else legs(*B), "lambda_td": legs(1, 2, 3, 4, 5), **extra}
    state, rate, slot, n_switch, atd, natd, _ = run(6, flags)
    assert np.all(natd == 1)  # 5 of 6 lambda_td: NATD whatever the latches say
    if support == "none":
        assert np.all(atd == 0) and n_switch[-1] == 0 and np.all(state[-1, A] == SWING_PROLONG)
        assert np.all(state[-1, B] == STANCE_PROLONG)
    else:
        assert np.all(atd == 1) and n_switch[-1] == 1 and slot[-1] == 1


def test_a_reflex_anywhere_blocks_the_exchange():
    def flags(k):
        return {"swing": legs(*A) if k < 2 else legs(*B), "lambda_td": ALL, "active": legs(0)}
    *_, n_switch, atd, _, _ = run(6, flags)
    assert atd[-1] == 1 and n_switch[-1] == 0


def test_liftoff_needs_an_alien_touchdown():
    """aTD_i: a leg of another slot touches down (lambda_td or landed; a leg that gave up does not count).
    The slot-0 legs are supported only as searches given up, the standing legs touch down: ATD holds, but the
    standing legs, who swing next, see no touchdown of another slot, so they may not lift off and the exchange
    waits; a slot-0 touchdown from sample 4 releases it."""
    def flags(k, release):
        td = ALL if (release and k >= 4) else legs(*B)
        return {"swing": legs(*A) if k < 2 else legs(*B), "lambda_td": td, "gaveup": legs(*A)}
    state, _, slot, n_switch, atd, _, alien = run(8, lambda k: flags(k, False))
    assert np.all(atd == 1) and np.all(alien[:, A] == 1) and np.all(alien[:, B] == 0)
    assert n_switch[-1] == 0 and np.all(state[-1, B] == STANCE_PROLONG)
    *_, n_switch, _, _, alien = run(8, lambda k: flags(k, True))
    assert np.all(alien[4:, B] == 1) and n_switch[3] == 0 and n_switch[4] == 1


def test_a_tetrapod_stance_part_ends_at_its_fraction_of_the_half_period():
    """Tetrapod (gamma 3), slot 0: L1 and R3 (slot 2) stand with j = (0 - 2 - 1) mod 3 = 0, so their part ends at
    the fraction (j + 1)/(gamma - 1) = 1/2 of T_half (minus p_tol); their stance rate is 3/4 (T_g = T_net), so
    with T_half = 0.8 s the network time reaches (0.5 - 1e-3) * 0.8 = 0.3992 s after 0.3992 / 0.75 = 0.5323 s.
    The FSM integrates that time from sample to sample: the transition comes within two samples after."""
    state, rate, *_ = run(100, lambda k: {"swing": legs(2, 4)}, gait=2, T_half=0.8)
    assert rate[1, 0] == pytest.approx(0.75) and state[1, 0] == STANCE
    k = int(np.argmax(state[:, 0] == STANCE_PROLONG))
    assert 0.5323 <= k * DT <= 0.5323 + 2 * DT + 1e-9, k
    assert np.all(state[: k, 0] == STANCE) and np.all(state[k:, 0] == STANCE_PROLONG)
    assert np.all(state[:, 1] == STANCE)  # L2 (slot 1, j = 1) stands to its PEP: target 1 is the stance's end


class Legs:
    """The FSM sampled one step at a time with flags chosen from its own outputs (a scripted robot):
    :meth:`sample` applies ``flags`` (six values per input) and returns the outputs after the sample."""

    def __init__(self, gait: int, **params) -> None:
        from cpgsim.harness.compile import compile_graph

        self.m = compile_graph(YuGaitFSM("fsm", gait=gait, **{"T_g": 5.0, "T_net": 5.0, "T_half": 1.0, **params}),
                               dt=DT)
        self.x, self.z, self.p = self.m.x0.copy(), self.m.z0.copy(), self.m.p0.copy()
        self.k = 0

    def sample(self, **flags) -> dict[str, np.ndarray]:
        m = self.m
        u = np.zeros(m.inputs.size)
        for name, values in flags.items():
            u[m.inputs.index("$" + name).slice] = values
        t = self.k * DT
        x, z = (np.asarray(a).ravel() for a in m.discrete(t, self.x, self.z, u, self.p))
        y = np.asarray(m.signals(t, x, z, u, self.p)).ravel()
        self.x, self.z, self.k = x, z, self.k + 1
        return {name: y[m.signals_layout.index(f"fsm.{name}").slice] for name in ("state", "slot", "n_switch", "rate")}


# the swing order of the module docstring's table (Yu Y16's slots as chosen here), written out by hand
TETRAPOD_ORDER = [{2, 4}, {1, 3}, {0, 5}]  # {L3, R2}, {L2, R1}, {L1, R3}
WAVE_ORDER = [{2}, {1}, {0}, {5}, {4}, {3}]  # L3, L2, L1, R3, R2, R1


@pytest.mark.parametrize("gait, order", [(1, [set(A), set(B)]), (2, TETRAPOD_ORDER), (3, WAVE_ORDER)])
def test_the_slots_follow_the_gait_tables_order_through_two_cycles(gait, order):
    """A scripted robot: a swinging leg's swing ends 3 samples after it began, a standing leg's part of the
    stance ends 3 samples after it began (its leader passes PEP: the swing flag rises and stays up while the
    leg holds in StanceProlong), every foot is down. The legs that swing
    in each slot must be the table's, in its order, twice round."""
    legs = Legs(gait)
    state, since = None, np.zeros(6)
    swinging: list[set] = []
    for _ in range(400):
        if state is None:  # the first sample: swings begin (flag 1), stances are done at once
            swing_flag = ALL
        else:
            swing_flag = np.select([state == SWING, state == STANCE, state == STANCE_PROLONG],
                                   [since < 3, since >= 3, True], False).astype(float)
        out = legs.sample(swing=swing_flag, lambda_td=ALL)
        since = np.where(state is not None and out["state"] == state, since + 1, 0) if state is not None \
            else np.zeros(6)
        state = out["state"]
        now = {i for i in range(6) if state[i] == SWING}
        if now and (not swinging or now != swinging[-1]):
            swinging.append(now)
        if len(swinging) > 2 * len(order):
            break
    assert swinging[:2 * len(order)] == order * 2


def test_a_reflex_that_aborted_a_stance_lets_the_landed_legs_start_their_stance_early():
    """Module docstring, "Early stance after an aborted stance": the tripod's slot-0 legs have swung and
    landed (SwingProlong, ``landed``); a reflex on L1 freezes the standing legs mid-stance (StanceProlong,
    aborted). When it ends the standing legs resume, and the landed legs start their stance at once; without
    the reflex they hold in SwingProlong until the switch."""
    def run_(reflex: bool) -> np.ndarray:
        legs = Legs(1)
        states = []
        for k in range(12):
            active = legs_(0) if reflex and 4 <= k <= 6 else np.zeros(6)
            out = legs.sample(swing=legs_(*A) if k < 2 else np.zeros(6), landed=legs_(*A), active=active,
                              lambda_td=legs_(*A))
            states.append(out["state"])
        return np.array(states)
    legs_ = legs
    with_reflex, without = run_(True), run_(False)
    assert np.all(without[2:][:, A] == SWING_PROLONG) and np.all(without[:, B] == STANCE)
    assert np.all(with_reflex[4:7][:, B] == STANCE_PROLONG)
    assert np.all(with_reflex[7:][:, B] == STANCE) and np.all(with_reflex[7:][:, A] == STANCE)


def _scripted(gait: int, reflex: bool = False, late: int = 0, samples: int = 600):
    """The scripted robot of the test above, with (``reflex``) every swinging leg running a reflex (``active``)
    in the 2nd to 4th samples of its swing, and (``late``) every foot that swung touching down (lambda_td)
    only ``late`` samples after its swing ended. Returns the swing sets in order and, per sample, the inputs
    (active, lambda_td) and outputs (state, slot, rate)."""
    legs_ = Legs(gait)
    state, since = None, np.zeros(6)
    swinging: list[set] = []
    trace = []
    td_off = np.zeros(6)  # samples since the swing ended, for the legs still in the air
    in_air = np.zeros(6, bool)
    for _ in range(samples):
        if state is None:
            swing_flag, active = ALL, np.zeros(6)
        else:
            swing_flag = np.select([state == SWING, state == STANCE, state == STANCE_PROLONG],
                                   [since < 3, since >= 3, True], False).astype(float)
            active = ((state == SWING) & (since >= 1) & (since <= 3)).astype(float) if reflex else np.zeros(6)
            in_air = (in_air | (state == SWING)) if late else in_air
            td_off = np.where(in_air & (state != SWING), td_off + 1, 0)
            in_air = in_air & ~(td_off > late)
        td = np.where(in_air, 0.0, 1.0)
        out = legs_.sample(swing=swing_flag, lambda_td=td, active=active)
        since = np.where(out["state"] == state, since + 1, 0) if state is not None else np.zeros(6)
        state = out["state"]
        trace.append((active.copy(), td.copy(), state.copy(), float(out["slot"][0]), out["rate"].copy()))
        now = {i for i in range(6) if state[i] == SWING}
        if now and (not swinging or now != swinging[-1]):
            swinging.append(now)
    return swinging, trace


ORDERS = [(1, [set(A), set(B)]), (2, TETRAPOD_ORDER), (3, WAVE_ORDER)]


@pytest.mark.parametrize("gait, order", ORDERS)
def test_a_reflex_in_every_slot_holds_the_standing_legs_and_keeps_the_order(gait, order):
    """Module docstring: while any leg runs a reflex, legs in Stance go to StanceProlong at once (rate 0) and
    no switch happens (SWITCH needs no reflex); the reflexing leg keeps running; when it ends the order of
    the table goes on, twice round."""
    swinging, trace = _scripted(gait, reflex=True)
    assert swinging[:2 * len(order)] == order * 2
    reflex_samples = 0
    for k, (active, _, state, slot, rate) in enumerate(trace):
        if active.any():
            reflex_samples += 1
            assert not np.any(state == STANCE), k  # every standing leg held
            assert np.all(rate[state == STANCE_PROLONG] == 0.0) and np.all(rate[active > 0] > 0.0)
            assert slot == trace[k - 1][3], k  # no switch while a reflex runs
    assert reflex_samples >= 3 * 2 * len(order)  # three samples of reflex in every slot seen


@pytest.mark.parametrize("gait, order", ORDERS)
@pytest.mark.parametrize("late", [2, 6])
def test_a_foot_that_lands_late_holds_the_switch_in_every_slot(gait, order, late):
    """Table 2 as used here: NATD (some feet down, not all) blocks the exchange, ATD (all six) allows it.
    Every swinging foot touches down ``late`` samples after its swing ended: no slot switch happens at a sample
    with a foot in the air, the order of the table still holds, twice round."""
    swinging, trace = _scripted(gait, late=late)
    assert swinging[:2 * len(order)] == order * 2
    switches = [k for k in range(1, len(trace)) if trace[k][3] != trace[k - 1][3]]
    assert len(switches) >= 2 * len(order) - 1
    for k in switches:
        assert np.all(trace[k][1] == 1.0), (k, trace[k][1])  # every foot down at the switch
        # and the switch did wait for the last foot: the sample before, some foot was still in the air
        assert np.any(trace[k - 1][1] == 0.0), k


def test_after_an_early_stance_the_switch_comes_and_the_landed_legs_stay_in_stance():
    """Module docstring, "Early stance after an aborted stance": a slot-0 leg in early Stance "counts as ready
    for the switch; at the switch it simply stays in Stance". The script of the test above; from sample 9 the
    standing legs' leaders pass their PEP (swing flag) and every foot is down: at 9 they go to StanceProlong
    (their part done), at 10 every leg is ready (slot-0 legs in Stance, the others in StanceProlong, done), ATD,
    no reflex, the next slot's legs see slot-0 feet down (aTD): the switch, B swings, A stays in Stance."""
    fsm = Legs(1)
    rows = []
    for k in range(12):
        rows.append(fsm.sample(swing=legs(*A) if k < 2 else legs(*B) if k >= 9 else np.zeros(6), landed=legs(*A),
                               active=legs(0) if 4 <= k <= 6 else np.zeros(6),
                               lambda_td=legs(*A) if k < 9 else ALL))
    state = np.array([r["state"] for r in rows])
    slot = np.array([r["slot"][0] for r in rows])
    assert np.all(state[7:9][:, A] == STANCE) and np.all(state[7:9][:, B] == STANCE)  # early stance, resumed
    assert np.all(state[9, B] == STANCE_PROLONG) and np.all(slot[:10] == 0)
    assert slot[10] == 1 and rows[10]["n_switch"][0] == 1
    assert np.all(state[10, B] == SWING) and np.all(state[10, A] == STANCE)


def test_natd_needs_some_but_not_all_feet_down():
    """Table 2: NATD = 0 < sum(lambda_td) < 6: no foot down is not NATD, one to five are, six are not."""
    for down, expect in (((), 0), ((3,), 1), ((0, 1, 2, 3, 4), 1), ((0, 1, 2, 3, 4, 5), 0)):
        *_, natd, _ = run(2, lambda k, down=down: {"swing": legs(*A), "lambda_td": legs(*down)})
        assert np.all(natd == expect), down


@pytest.mark.parametrize("late_leg", [0, 1, 2, 3, 4, 5])
def test_the_exchange_waits_for_every_single_leg(late_leg):
    """SWITCH needs every leg ready: the tripod exchange of test_switch_needs_every_leg_ready_atd_and_no_reflex,
    with one leg late -- a slot-0 leg still swinging (its swing flag stays up until sample 4) or a standing leg
    whose leader passes its PEP only at sample 4 (its flag rises then). The exchange waits for that leg: the
    others are ready from sample 2, the switch comes at sample 5 (the sample after the late leg's part ends;
    StanceProlong needs its part done at the sample of the switch)."""
    def flags(k):
        swing = legs(*A) if k < 2 else legs(*B)
        if k < 4:
            swing[late_leg] = 1.0 if late_leg in A else 0.0
        else:
            swing[late_leg] = 0.0 if late_leg in A else 1.0
        return {"swing": swing, "lambda_td": ALL}
    state, rate, slot, n_switch, *_ = run(8, flags)
    assert np.all(n_switch[:5] == 0) and np.all(slot[:5] == 0)
    assert np.all(n_switch[5:] == 1) and np.all(slot[5:] == 1)


def test_a_stance_begun_at_a_switch_counts_its_progress_from_the_switch():
    """tau (the network time run since the stance began) restarts when a leg goes from SwingProlong to Stance.
    Tetrapod, T_g = T_net = 5 s, T_half = 0.8 s: swing rate 3/2, stance rate 3/4 (Y16 over omega1). Slot 0: L3
    and R2 swing (flag up for samples 0-59: about 0.9 s of network time; their swing ends one sample before
    the switch, so no sample in SwingProlong but that one), L1 and R3 end their part at 0.53 s (the tetrapod
    test above), L2 and R1 (who swing next) pass their PEP at sample 60. Every foot is down: the switch to
    slot 1 comes at sample 61. In slot 1, L3 stands with j = (1 - 0 - 1) mod 3 = 0: its part ends at
    (1/2 - p_tol) * T_half = 0.3992 s of network time, 0.3992 / 0.75 = 53.2 samples after the switch, within two
    samples (as above). Counted from its swing instead (0.9 > 0.3992), the part would end at once."""
    fsm = Legs(2, T_half=0.8)
    rows = []
    for k in range(140):
        swing = np.zeros(6)
        if k < 60:
            swing[[2, 4]] = 1.0
        if k >= 60:
            swing[[1, 3]] = 1.0  # L2, R1 leaders past PEP (and their swing after the switch)
        rows.append(fsm.sample(swing=swing, lambda_td=ALL))
    state = np.array([r["state"] for r in rows])
    slot = np.array([r["slot"][0] for r in rows])
    ks = int(np.argmax(slot == 1))
    assert ks == 61 and state[ks, 2] == STANCE and state[ks - 1, 2] == SWING_PROLONG
    k_end = ks + int(np.argmax(state[ks:, 2] == STANCE_PROLONG))
    assert 53.2 <= k_end - ks <= 53.2 + 2, k_end - ks
    assert np.all(state[ks:k_end, 2] == STANCE)


@pytest.mark.parametrize("down", range(6))
def test_atd_alien_is_a_touchdown_of_any_leg_of_another_slot(down):
    """aTD_i: some leg j with slot(j) != slot(i) touches down. One foot down (lambda_td of leg ``down`` only):
    in the tripod every leg of the other group sees it, the legs of its own group (itself included) do not."""
    *_, alien = run(2, lambda k: {"swing": legs(*A), "lambda_td": legs(down)})
    own = A if down in A else B
    expect = np.array([0.0 if i in own else 1.0 for i in range(6)])
    assert np.all(alien == expect)


def test_only_the_legs_that_swing_next_need_an_alien_touchdown():
    """The mirror of test_liftoff_needs_an_alien_touchdown: the slot-0 legs touch down, the standing legs (who
    swing next) are supported only as searches given up. ATD holds; the legs that swing next see slot-0 feet
    down (aTD); the slot-0 legs, who stand next, see no alien touchdown and need none: the exchange happens."""
    def flags(k):
        return {"swing": legs(*A) if k < 2 else legs(*B), "lambda_td": legs(*A), "gaveup": legs(*B)}
    state, _, slot, n_switch, atd, _, alien = run(6, flags)
    assert np.all(atd == 1) and np.all(alien[:, B] == 1) and np.all(alien[:, A] == 0)
    assert n_switch[-1] == 1 and slot[-1] == 1 and np.all(state[-1, B] == SWING)


def test_the_gait_table_has_yu_y16_slot_counts_and_names():
    """Y16: gamma = 2 (tripod), 3 (tetrapod), 6 (wave) slots per cycle; each slot table uses exactly gamma slots,
    each of them at least once (the module docstring's table). Names and numbers select the same gait; an
    unknown name or number is refused."""
    from cpgsim.components.core import ParameterError
    from cpgsim.components.yu.fsm import GAITS, gait_id

    assert {g: (name, gamma) for g, (name, gamma, _) in GAITS.items()} == {1: ("tripod", 2), 2: ("tetrapod", 3),
                                                                           3: ("wave", 6)}
    for _, gamma, slots in GAITS.values():
        assert sorted(set(slots)) == list(range(gamma)) and len(slots) == 6
    assert [gait_id(n) for n in ("tripod", "tetrapod", "wave")] == [1, 2, 3] == [gait_id(g) for g in (1, 2, 3)]
    for bad in ("gallop", "Tripod", 0, 4):
        with pytest.raises(ParameterError):
            gait_id(bad)


def test_the_last_part_of_a_stance_ends_only_at_the_pep():
    """Tetrapod slot 0: L2 (slot 1) stands with j = (0 - 1 - 1) mod 3 = 1, target (j + 1)/(gamma - 1) = 1: its
    part is the stance's end, which comes when its leader passes its PEP (the swing flag), not when its network
    time reaches T_half. With T_half = 0.8 s at the stance rate 3/4 that time passes at 1.07 s; the leg still
    stands at 1.5 s, and goes to StanceProlong at the sample its flag rises (1.5 s)."""
    state, *_ = run(160, lambda k: {"swing": legs(2, 4) if k < 150 else legs(1, 2, 4)}, gait=2, T_half=0.8)
    assert np.all(state[:150, 1] == STANCE) and np.all(state[150:, 1] == STANCE_PROLONG)


def test_the_state_output_uses_the_documented_codes():
    """The ``state`` port's description (module docstring, docs/blocks.md): 0 Swing, 1 Stance, 2 SwingProlong,
    3 StanceProlong -- numbers written here, not the module's constants: a reflex on L1 while slot-0 legs swing
    (tripod) holds the standing legs in 3; a slot-0 leg whose swing flag fell waits in 2."""
    from cpgsim.components.yu.fsm import STATE_NAMES

    assert STATE_NAMES == ("Swing", "Stance", "SwingProlong", "StanceProlong")
    state, *_ = run(3, lambda k: {"swing": legs(0, 4) if k else legs(*A), "active": legs(0) if k else np.zeros(6)})
    assert list(state[0]) == [0, 1, 0, 1, 0, 1]
    assert list(state[2]) == [0, 3, 2, 3, 0, 3]


def test_a_reflex_of_one_sample_still_counts_as_an_abort():
    """The abort is latched "from the moment a reflex sends a Stance leg to StanceProlong" (module docstring):
    a reflex on L1 at sample 4 only. At 4 the standing legs go to StanceProlong; at 5 no reflex runs, they
    resume (their parts are not done) and the landed slot-0 legs start their stance at once, as after the
    three-sample reflex above."""
    fsm = Legs(1)
    state = np.array([fsm.sample(swing=legs(*A) if k < 2 else np.zeros(6), landed=legs(*A), lambda_td=legs(*A),
                                 active=legs(0) if k == 4 else np.zeros(6))["state"] for k in range(8)])
    assert np.all(state[2:4][:, A] == SWING_PROLONG) and np.all(state[4, B] == STANCE_PROLONG)
    assert np.all(state[5:] == STANCE)


def test_the_stance_fraction_tolerance_ends_a_part_early():
    """``p_tol``: a part ends when the progress reaches its fraction minus p_tol. The tetrapod test above with
    p_tol = 0.2: L1's part (fraction 1/2) ends at (0.5 - 0.2) * 0.8 s = 0.24 s of network time, 0.24 / 0.75 =
    0.32 s, within two samples (with p_tol added instead it would be 0.7 * 0.8 / 0.75 = 0.75 s)."""
    state, *_ = run(100, lambda k: {"swing": legs(2, 4)}, gait=2, T_half=0.8, p_tol=0.2)
    k = int(np.argmax(state[:, 0] == STANCE_PROLONG))
    assert 0.32 <= k * DT <= 0.32 + 2 * DT + 1e-9, k


def test_the_first_leg_too_needs_an_alien_touchdown_to_swing_next():
    """Wave (one leg per slot, L1 in slot 2): every standing leg's leader is past its PEP (swing flags up: parts
    done); L3 swings (slot 0) until sample 3, the switch to slot 1 comes at 4 (everything down), and L3's flag
    rises again (its stance part done at once). In slot 1 L2
    swings until sample 6; from sample 4 only L1's foot is down, the others are supported as searches given
    up: ATD holds, but L1, who swings next, sees no touchdown of another leg, so the switch to slot 2 waits --
    until every foot is down again at sample 10."""
    def flags(k):
        swing = np.ones(6)
        if k in (3, 4):
            swing[2] = 0.0  # L3's swing ends; in its stance from the switch its leader is past PEP at once
        if k >= 6:
            swing[1] = 0.0  # L2's swing ends
        if 4 <= k < 10:
            return {"swing": swing, "lambda_td": legs(0), "gaveup": legs(1, 2, 3, 4, 5)}
        return {"swing": swing, "lambda_td": ALL}
    state, _, slot, n_switch, atd, _, alien = run(14, flags, gait=3)
    assert np.all(slot[:4] == 0) and np.all(slot[4:10] == 1) and np.all(slot[10:] == 2)
    assert np.all(atd[4:10] == 1) and np.all(alien[4:10, 0] == 0) and state[10, 0] == SWING


def test_a_leg_whose_early_stance_ended_before_the_switch_does_not_hold_the_gait():
    """Module docstring: after an abort a landed slot-0 leg starts its stance early, "it ends its stance (at its
    PEP) early and waits in StanceProlong for the next switch". Here that end comes before the switch: the
    reflex on L1 at samples 4-6 aborts the standing legs, at 7 they resume and the landed slot-0 legs start
    their stance; at 9 the slot-0 legs' leaders pass their PEP (swing flags up: StanceProlong); the standing
    legs' parts end at 12 and their feet touch down then (ATD from 12). Every leg is then waiting on its part's
    end: the switch must come at 13 (StanceProlong at 12, ready at 13), B swings."""
    fsm = Legs(1)
    rows = []
    for k in range(18):
        swing = legs(*A) if k < 2 else np.zeros(6)
        if k >= 9:
            swing[A] = 1.0
        if k >= 12:
            swing[B] = 1.0
        rows.append(fsm.sample(swing=swing, landed=legs(*A), lambda_td=legs(*A) if k < 12 else ALL,
                               active=legs(0) if 4 <= k <= 6 else np.zeros(6)))
    state = np.array([r["state"] for r in rows])
    slot = np.array([r["slot"][0] for r in rows])
    assert np.all(state[7:9][:, A] == STANCE) and np.all(state[9:13][:, A] == STANCE_PROLONG)
    assert np.all(slot[:13] == 0) and np.all(slot[13:] == 1) and np.all(state[13, B] == SWING)


@pytest.mark.parametrize("r3_done_at, early", [(8, False), (12, True)])
def test_the_early_stance_waits_for_a_standing_leg_still_to_resume(r3_done_at, early):
    """Module docstring: after an abort a landed slot-0 leg starts its stance early only when it "sees the
    standing legs resume (no reflex runs and some leg of another slot has its stance part still to do)". A
    one-sample reflex on L1 at 4; the slot-0 feet land only at 10; L2 and R1 end their parts at 8, R3 at
    ``r3_done_at``; the standing feet never touch down (no ATD, no switch). With R3 still standing at 10 the
    slot-0 legs start their stance then; with every standing part done they wait in SwingProlong."""
    fsm = Legs(1)
    rows = []
    for k in range(14):
        swing = legs(*A) if k < 2 else np.zeros(6)
        swing[[1, 3]] = 1.0 if k >= 8 else 0.0
        swing[5] = 1.0 if k >= r3_done_at else 0.0
        down = legs(*A) if k >= 10 else np.zeros(6)
        rows.append(fsm.sample(swing=swing, landed=down, lambda_td=down,
                               active=legs(0) if k == 4 else np.zeros(6)))
    state = np.array([r["state"] for r in rows])
    assert np.all(state[2:10][:, A] == SWING_PROLONG) and rows[-1]["n_switch"][0] == 0
    assert np.all(state[10:12][:, A] == (STANCE if early else SWING_PROLONG))


def test_the_abort_latch_holds_for_its_slot_only():
    """The ``aborted`` state is "a reflex aborted a stance in this slot" (its description; module docstring,
    early stance after an aborted stance): set by the sample-4 reflex on L1 of the test above, held while
    slot 0 lasts, cleared by the switch to slot 1 (sample 9, when every leader is past its PEP with all feet
    down), so a later slot does not resume as if its stance had been aborted."""
    fsm = Legs(1)
    latch = fsm.m.dstates.index("fsm.aborted").slice
    aborted, slot = [], []
    for k in range(14):
        swing = legs(*A) if k < 2 else (np.zeros(6) if k < 8 else ALL)
        down = legs(*A) if k < 8 else ALL
        out = fsm.sample(swing=swing, landed=down, lambda_td=down, active=legs(0) if k == 4 else np.zeros(6))
        aborted.append(float(fsm.z[latch][0]))
        slot.append(int(out["slot"][0]))
    assert aborted[:4] == [0.0] * 4 and aborted[4:9] == [1.0] * 5
    assert slot[8] == 0 and slot[9] == 1 and aborted[9:] == [0.0] * 5


def test_a_reflex_with_one_leg_in_stance_still_latches_the_abort():
    """The abort is latched when a reflex sends *a* Stance leg to StanceProlong (module docstring), so one leg
    is enough: wave gait, slot 0 (L3 swings); L1's part of the stance is not done (its swing flag down),
    the other four are done and hold in StanceProlong. A reflex on L3 at sample 3 sends L1 to StanceProlong
    and latches the abort; L1 resumes its stance at sample 4 (its part is still not done)."""
    fsm = Legs(3)
    latch = fsm.m.dstates.index("fsm.aborted").slice
    swing, down = ALL.copy(), ALL.copy()
    swing[0], down[2] = 0.0, 0.0
    states, aborted = [], []
    for k in range(6):
        out = fsm.sample(swing=swing, landed=down, lambda_td=down, active=legs(2) if k == 3 else np.zeros(6))
        states.append(out["state"].astype(int).tolist())
        aborted.append(float(fsm.z[latch][0]))
    held = [STANCE_PROLONG] * 3
    assert states[2] == [STANCE, STANCE_PROLONG, SWING, *held]  # exactly one leg in Stance before the reflex
    assert states[3] == [STANCE_PROLONG, STANCE_PROLONG, SWING, *held] and aborted[:3] == [0.0] * 3
    assert aborted[3:] == [1.0] * 3 and states[4][0] == STANCE
