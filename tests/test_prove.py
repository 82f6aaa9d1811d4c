"""Tests of the limit-cycle proof (``cpgsim verify --prove``): ball tape evaluation, the validated Taylor
integrator, the Krawczyk test, multiplier enclosures, certificates and the CLI.

References are independent of the code under test: the classical Van der Pol period at mu = 1
(6.6632868593231301896996820305..., the literature value quoted in the issue), closed-form solutions of
linear systems, CasADi's own double evaluation, mpmath's Taylor ODE solver ``odefun`` at 30 digits, and
the numeric Floquet multipliers of ``verify`` (CVODES sensitivities).
"""

from __future__ import annotations

import copy
import json
import math
import re
from decimal import Decimal

import casadi as ca
import numpy as np
import pytest
from flint import arb, arb_mat

from cpgsim.cli.main import main
from cpgsim.components.library import damped_oscillator, single_vdp
from cpgsim.verify.ball import (
    NotAnalytic,
    Tape,
    arb_ops,
    augmented_function,
    iv_taylor_coefficients,
)
from cpgsim.verify.prove import (
    ProofOptions,
    exact_str,
    interval_text,
    multiplier_enclosures,
    parse_exact,
    prove_report,
    prove_system,
    system_of_graph,
    tape_constants,
)
from cpgsim.verify.result import VerifyOptions
from cpgsim.verify.shooting import verify
from cpgsim.verify.taylor import Integrator, precision, taylor_coefficients

VDP_T_MU1 = "6.6632868593231301896996820305"  # classical x'' - mu (1 - x^2) x' + x = 0 at mu = 1
FAST = VerifyOptions(compute_sync=False)


def classical_vdp():
    """Yu Y2 is ``x' = y, y' = -eps (b x^2 - 1) y - omega^2 x``, i.e. ``x'' - eps (1 - b x^2) x' + omega^2 x = 0``:
    with ``b = 1`` and ``omega = 1`` it is the classical Van der Pol equation with ``mu = eps``; so
    ``eps = b = omega = 1`` is the classical oscillator at ``mu = 1``."""
    return single_vdp(eps=1.0, b=1.0, omega=1.0)


@pytest.fixture(scope="module")
def vdp_proof():
    g = classical_vdp()
    rep = verify(g, options=FAST)
    return g, rep, prove_report(g, rep)


# -- ball evaluation of the tape -------------------------------------------------------------------

def test_tape_balls_contain_casadi_values() -> None:
    f, _ = system_of_graph(single_vdp(eps=0.7, b=2.0, omega=1.3))
    aug = augmented_function(f)
    rng = np.random.default_rng(1)
    for fn in (f, aug):
        tape = Tape(fn)
        for _ in range(5):
            x = rng.uniform(-2, 2, fn.nnz_in(0))
            want = np.asarray(fn(x)).ravel()
            with precision(128):
                got = tape.evaluate([arb(float(v)) for v in x], arb_ops())
            for w, g in zip(want, got, strict=True):
                assert abs(float(g.mid()) - w) <= 1e-13 * (1 + abs(w))
                assert g.rad() < 1e-30  # a point evaluation at 128 bits is sharp


def test_elementary_functions_and_fallback_series_agree() -> None:
    x = ca.SX.sym("x", 2)
    f = ca.Function("f", [x], [ca.vertcat(ca.sin(x[1]) * ca.exp(-x[0]), ca.sqrt(1 + x[0] ** 2) - ca.cos(x[1]) / 3)])
    tape = Tape(f)
    with precision(128):
        a = taylor_coefficients(tape, [arb(0.3), arb(-0.2)], 10)
    from mpmath import iv
    iv.prec = 128
    b = iv_taylor_coefficients(tape, [0.3, -0.2], 10)
    iv.prec = 53
    for ca_k, cb_k in zip(a, b, strict=True):
        for u, v in zip(ca_k, cb_k, strict=True):
            assert abs(float(u.mid()) - float(v.mid)) <= 1e-14 * (1 + abs(float(u.mid())))


def test_non_analytic_operations_are_rejected() -> None:
    x = ca.SX.sym("x", 2)
    for expr in (ca.if_else(x[0] > 0, x[1], -x[1]), ca.fabs(x[0]), ca.fmax(x[0], x[1])):
        with pytest.raises(NotAnalytic):
            Tape(ca.Function("f", [x], [ca.vertcat(expr, x[0])]))


# -- validated integration -------------------------------------------------------------------------

def test_taylor_step_encloses_the_exact_rotation() -> None:
    x = ca.SX.sym("x", 2)
    tape = Tape(ca.Function("f", [x], [ca.vertcat(x[1], -x[0])]))
    with precision(128):
        integ = Integrator(tape, 20)
        st = integ.step([arb(1), arb(0)], arb(0.25))
        assert st is not None
        z = st.at(arb(0.25))
        assert z[0].contains(arb(0.25).cos()) and z[1].contains(-arb(0.25).sin())
        assert max(float(v.rad()) for v in z) < 1e-20
        assert integ.step([arb(1), arb(0)], arb(50.0)) is None  # the Picard test fails for a far too long step
        # a wrong claim is caught: the enclosure excludes cos(0.25) + 1e-15
        assert not z[0].contains(arb(0.25).cos() + arb(1e-15))


def test_multiplier_enclosures_of_known_matrices() -> None:
    with precision(128):
        rot = arb_mat([[arb(0.5), arb(-0.3)], [arb(0.3), arb(0.5)]])
        mus = multiplier_enclosures(rot)
        want = abs(complex(0.5, 0.3))
        assert len(mus) == 2
        for mu in mus:
            assert mu["abs"][0] <= want <= mu["abs"][1] and mu["abs"][1] - mu["abs"][0] < 1e-12
            assert not mu["real"] and min(abs(mu["im"][0]), abs(mu["im"][1])) > 0.29
        diag = arb_mat([[arb(0.9, 1e-9), arb(0, 1e-9)], [arb(0, 1e-9), arb(-0.2, 1e-9)]])
        mus = multiplier_enclosures(diag)
        assert mus[0]["real"] and mus[0]["re"][0] <= 0.9 <= mus[0]["re"][1] and mus[0]["im"] == [0.0, 0.0]
        assert mus[1]["re"][0] <= -0.2 <= mus[1]["re"][1] and mus[1]["abs"][0] <= 0.2 <= mus[1]["abs"][1]
        assert mus[0]["inside_unit_circle"]
        big = arb_mat([[arb(1.0, 1e-6)]])
        assert not multiplier_enclosures(big)[0]["inside_unit_circle"]  # touches the unit circle
        for tiny in (arb_mat([[arb(0, 1.344e-4)]]),  # a modulus is never negative, even of a ball around 0
                     arb_mat([[arb(0, 1e-4), arb(0, 1e-4)], [arb(0, 1e-4), arb(0.5, 1e-9)]])):
            for mu in multiplier_enclosures(tiny):
                assert 0.0 <= mu["abs"][0] <= mu["abs"][1]
        assert multiplier_enclosures(arb_mat([[arb(0, 1.344e-4)]]))[0]["abs"][1] >= 1.344e-4


def _printed_intervals(text: str) -> list[tuple[Decimal, Decimal]]:
    """Every ``[a, b]`` of numbers in ``text``, as exact decimals (read literally)."""
    num = r"(-?[0-9.]+(?:e[-+]?[0-9]+)?)"
    return [(Decimal(a), Decimal(b)) for a, b in re.findall(rf"\[{num}, {num}\]", text)]


def _contains(printed: tuple[Decimal, Decimal], lo: float, hi: float) -> bool:
    return printed[0] <= Decimal(lo) and Decimal(hi) <= printed[1]


@pytest.mark.slow
def test_not_proved_names_the_knob(vdp_proof) -> None:
    """At 64 bits and order 8 the classical cycle (proved at the defaults) is not proved: the reason says
    that more bits or a higher order may succeed."""
    g, rep, _ = vdp_proof
    res = prove_report(g, rep, opts=ProofOptions(precision=64, order=8))
    assert not res.proved and res.reason.startswith("not proved")
    assert "may succeed" in res.reason and "--precision" in res.reason and "now 64" in res.reason
    assert "\n" not in res.reason


def test_the_proof_states_the_tape_doubles() -> None:
    """omega = 0.9 enters the equations as the double nearest 0.9, squared and rounded to a double: the
    proof states those exact binary values (not the decimals 0.9 and 0.81)."""
    f, _ = system_of_graph(single_vdp(eps=0.37, b=2.5, omega=0.9))
    consts = tape_constants(Tape(f))
    omega2 = Decimal(0.9) * Decimal(0.9)  # exact product of the doubles
    got = [Decimal(c["exact"]) for c in consts]
    assert all(Decimal(float(c["repr"])) == Decimal(c["exact"]) for c in consts)  # repr names that double
    near = [v for v in got if abs(v - omega2) < Decimal("1e-15")]
    assert len(near) == 1 and near[0] != Decimal("0.81") and near[0] != omega2  # rounded once more
    assert near[0] == Decimal(0.9 * 0.9)  # ... to the nearest double (IEEE product)
    assert Decimal(0.37) in got and Decimal("0.37") not in got


@pytest.mark.slow
def test_proof_output_states_what_was_proved(vdp_proof) -> None:
    from cpgsim.cli.commands.verify import _proof_text

    g, _, res = vdp_proof
    d = res.to_json()["proved_for"]
    assert "tape" in d["statement"] and d["tape_constants"]
    assert {p["path"] for p in d["parameters"]} >= {"z.eps", "z.b", "z.omega"}
    assert res.certificate is not None and res.certificate["tape_constants"] == d["tape_constants"]
    assert "proved for the tape constants" in _proof_text(res)


def test_interval_text_rounds_outward() -> None:
    # 0.1 is the double 0.1000000000000000055...: rounding to nearest prints "0.1", which excludes it
    lo, hi = (Decimal(x) for x in interval_text(0.1, 0.1, 3)[1:-1].split(", "))
    assert lo <= Decimal(0.1) <= hi and hi > Decimal("0.1")
    # the period: the doubles around 7.0547221825750584... printed at 15 digits still contain it
    lo, hi = (Decimal(x) for x in interval_text(7.054722182575058, 7.054722182575059, 15)[1:-1].split(", "))
    assert lo <= Decimal("7.0547221825750584") <= hi
    lo, hi = (Decimal(x) for x in interval_text(-1.344e-4, 2.5e-7, 2)[1:-1].split(", "))
    assert lo <= Decimal(-1.344e-4) and Decimal(2.5e-7) <= hi


@pytest.mark.slow
def test_every_printed_interval_contains_the_json_one(vdp_proof) -> None:
    from cpgsim.cli.commands.verify import _proof_text

    _, _, res = vdp_proof
    d = res.to_json()
    text = _proof_text(res)
    got = _printed_intervals(text)
    want = [d["period"], d["period"]]  # the reason line, then the period line
    for mu in d["multipliers"]:
        want += [mu["abs"], mu["re"], mu["im"]]
    assert len(got) == len(want), text
    for printed, (lo, hi) in zip(got, want, strict=True):
        assert _contains(printed, lo, hi), (printed, lo, hi)


# -- proofs ----------------------------------------------------------------------------------------

@pytest.mark.slow
def test_classical_van_der_pol_period_is_enclosed(vdp_proof) -> None:
    _, _, res = vdp_proof
    assert res.proved and res.stable, res.reason
    assert res.period.contains(arb(VDP_T_MU1))
    assert float(2 * res.period.rad()) < 1e-6
    # and the enclosure is not trivially wide: it excludes the reference shifted by 1e-9
    assert not res.period.contains(arb(VDP_T_MU1) + arb(1e-9))
    d = res.to_json()
    assert d["period"][0] <= float(VDP_T_MU1) <= d["period"][1]
    assert set(d) >= {"proved", "period", "section", "box", "multipliers", "method", "wall_time_s"}
    assert d["section"]["state"] == "z.x" and d["section"]["level"] == 0.0


@pytest.mark.slow
def test_numeric_multipliers_lie_in_the_proved_enclosures(vdp_proof) -> None:
    _, rep, res = vdp_proof
    num = rep.cycle.nontrivial
    assert len(num) == len(res.multipliers) == 1
    mu = res.multipliers[0]
    # verify's CVODES monodromy is accurate to about 1e-9 relative; the enclosure is far narrower
    assert mu["abs"][0] - 1e-10 <= abs(num[0]) <= mu["abs"][1] + 1e-10
    assert mu["abs"][1] - mu["abs"][0] < 1e-8  # 192 bits: about 1e-9 (wrapping over the box)
    assert mu["real"] and mu["abs"][1] < 1e-3  # strongly attracting at mu = 1


def test_harmonic_oscillator_is_never_proved() -> None:
    g = damped_oscillator(zeta=0.0, omega=2.0)  # x'' + 4 x = 0: a centre, every orbit is periodic
    f, names = system_of_graph(g)
    res = prove_system(f, names, np.array([1.0, 0.0]), math.pi, opts=ProofOptions(precision=128, order=20))
    assert not res.proved and "singular" in res.reason
    rep = verify(g, options=FAST)
    res = prove_report(g, rep, opts=ProofOptions(precision=128, order=20))
    assert not res.proved and res.exit_code == 1
    assert "will not help" in res.reason  # a centre is not a matter of bits or order
    g = damped_oscillator()  # decays to the origin: no orbit at all
    res = prove_report(g, verify(g, options=FAST))
    assert not res.proved and "no periodic orbit" in res.reason


@pytest.mark.slow  # several seconds (the quick tier proves the classical period)
def test_a_box_that_excludes_the_orbit_fails(vdp_proof) -> None:
    g, rep, good = vdp_proof
    f, names = system_of_graph(g)
    x = rep.cycle.x0
    r = float(good.radius)
    res = prove_system(f, names, x, rep.cycle.period, "z.x", ProofOptions(radius=r),
                       center_shift=3.0, monodromy=rep.cycle.monodromy)
    assert not res.proved and "Krawczyk test failed" in res.reason
    res = prove_system(f, names, x, rep.cycle.period, "z.x", ProofOptions(radius=r),
                       monodromy=rep.cycle.monodromy)
    assert res.proved  # the same box, centred on the orbit, passes


@pytest.mark.slow
def test_higher_precision_and_order_narrow_the_enclosures(vdp_proof) -> None:
    g, rep, base = vdp_proof  # 192 bits, order 32
    f, names = system_of_graph(g)
    fine = prove_system(f, names, rep.cycle.x0, rep.cycle.period, "z.x", ProofOptions(precision=256, order=40),
                        monodromy=rep.cycle.monodromy)
    assert fine.proved
    assert fine.period.rad() < base.period.rad() * 1e-6
    assert fine.period.overlaps(base.period)
    w = [m["abs"][1] - m["abs"][0] for m in (base.multipliers[0], fine.multipliers[0])]
    assert w[1] <= w[0]


@pytest.mark.slow
def test_enclosures_contain_an_mpmath_reference(vdp_proof) -> None:
    """mpmath's ``odefun`` (its own Taylor method, 30 digits) from the proved fixed point crosses the
    section inside the period enclosure and returns into the box."""
    import mpmath

    _, _, res = vdp_proof
    mpmath.mp.dps = 30
    try:
        with precision(256):  # decimal strings of the exact binary numbers
            y0 = mpmath.mpf(res.box_center[0].mid().str(40, radius=False))
            lo = mpmath.mpf(res.period.lower().str(40, radius=False))
            hi = mpmath.mpf(res.period.upper().str(40, radius=False))
        sol = mpmath.odefun(lambda t, v: [v[1], (1 - v[0] ** 2) * v[1] - v[0]], 0, [mpmath.mpf(0), y0])
        assert sol(lo)[0] < 0 < sol(hi)[0]  # z.x crosses 0 upward inside the enclosure
        t_star = mpmath.findroot(lambda t: sol(t)[0], (lo + hi) / 2)
        assert lo <= t_star <= hi
        back = sol(t_star)[1]  # z.y at the return: the orbit closes inside the proved box
        assert abs(back - y0) < float(res.radius)
    finally:
        mpmath.mp.dps = 15


@pytest.mark.slow
def test_network_proof_and_its_multipliers() -> None:
    from cpgsim.components.networks import leader_follower_network

    g = leader_follower_network()
    rep = verify(g, options=FAST)
    res = prove_report(g, rep)
    assert res.proved and res.stable, res.reason
    assert float(2 * res.period.rad()) < 1e-6
    assert abs(float(res.period.mid()) - rep.cycle.period) < 1e-8  # CVODES shooting at rtol 1e-11
    num = sorted(np.abs(rep.cycle.nontrivial), reverse=True)
    assert len(num) == len(res.multipliers) == 5
    for v, mu in zip(num, res.multipliers, strict=True):
        assert mu["abs"][0] - 1e-8 <= v <= mu["abs"][1] + 1e-8
        assert mu["abs"][1] < 1


# -- CLI -------------------------------------------------------------------------------------------

MU1 = ["--set", "z.eps=1", "--set", "z.b=1", "--set", "z.omega=1"]


@pytest.fixture(scope="module")
def cli_cert(tmp_path_factory):
    """``cpgsim verify vdp (mu = 1) --prove --json --certificate FILE``: (exit code, JSON, certificate path)."""
    import contextlib
    import io

    tmp = tmp_path_factory.mktemp("prove_cli")
    cert = tmp / "vdp.cert.json"
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        rc = main(["verify", "vdp", *MU1, "--prove", "--json", "--samples", "0", "--no-plot", "-o", str(tmp / "o"),
                   "--certificate", str(cert)])
    return rc, json.loads(buf.getvalue()), cert


@pytest.mark.slow  # several seconds (the quick tier proves the classical period)
def test_cli_prove_json_and_certificate_check(cli_cert, capsys) -> None:
    rc, out, cert = cli_cert
    assert rc == 0
    assert out["status"] == "stable-cycle" and "floquet_multipliers" in out  # the verify report is kept
    p = out["proof"]
    assert p["proved"] and p["period"][0] <= float(VDP_T_MU1) <= p["period"][1]
    assert set(p) >= {"proved", "period", "section", "box", "multipliers", "method", "wall_time_s"}
    assert set(p["multipliers"][0]) >= {"abs", "re", "im"}
    assert (cert.parent / "o" / "proof.json").exists()
    capsys.readouterr()
    assert main(["verify", "vdp", "--check-certificate", str(cert)]) == 0
    printed = _printed_intervals(capsys.readouterr().out)  # the checker's recomputed period, read literally
    assert len(printed) == 1 and printed[0][0] <= Decimal(VDP_T_MU1) <= printed[0][1]


@pytest.mark.slow
def test_cli_tampered_certificates_fail(cli_cert, tmp_path) -> None:
    _, _, cert = cli_cert
    good = json.loads(cert.read_text())
    path = tmp_path / "bad.json"

    def check(bad: dict) -> int:
        path.write_text(json.dumps(bad))
        return main(["verify", "vdp", "--check-certificate", str(path)])

    # a period enclosure that misses the true period
    bad = copy.deepcopy(good)
    with precision(192):
        bad["claims"]["period"]["mid"] = exact_str(parse_exact(bad["claims"]["period"]["mid"]) + arb(1e-6))
    assert check(bad) == 1
    bad = copy.deepcopy(good)
    with precision(192):  # the box moved off the orbit by three radii
        bad["s_hat"][0] = exact_str(parse_exact(bad["s_hat"][0]) + 3 * parse_exact(bad["radius"]))
    assert check(bad) == 1
    bad = copy.deepcopy(good)  # other equations (tape digest)
    bad["params"]["z.eps"] = 0.9
    assert check(bad) == 1
    bad = copy.deepcopy(good)  # a stated tape constant that is not in the tape
    bad["tape_constants"][0]["exact"] = "0.5"
    assert check(bad) == 1
    bad = copy.deepcopy(good)  # a multiplier claim that is not what the interval computation gives
    bad["claims"]["multipliers"][0]["abs"] = [0.5, 0.6]
    assert check(bad) == 1
    assert check(good) == 0


@pytest.mark.slow
def test_every_stated_claim_is_checked(cli_cert, tmp_path, capsys) -> None:
    """Each flag must agree with its own stated enclosure, and each enclosure contain the recomputed one:
    a certificate is accepted only if everything it says is proved."""
    _, _, cert = cli_cert
    good = json.loads(cert.read_text())
    assert good["claims"]["multipliers"][0]["real"] and good["claims"]["stable"]
    path = tmp_path / "claims.json"

    def check(edit) -> int:
        bad = copy.deepcopy(good)
        edit(bad["claims"], bad["claims"]["multipliers"][0])
        path.write_text(json.dumps(bad))
        return main(["verify", "vdp", "--check-certificate", str(path)])

    def widened_inside(c, mu):  # |mu| in [0, 1.5] is not inside the unit circle, whatever the flag says
        mu["abs"] = [0.0, 1.5]

    def widened_honest(c, mu):  # the same enclosure with honest flags claims less, and all of it holds
        mu["abs"], mu["inside_unit_circle"], c["stable"] = [0.0, 1.5], False, False

    def stable_without_flags(c, mu):
        mu["abs"], mu["inside_unit_circle"] = [0.0, 1.5], False

    def real_with_imaginary_part(c, mu):  # real = true, but the stated im enclosure is not [0, 0]
        mu["im"] = [-0.1, 0.1]

    def flipped_flag(c, mu):
        mu["inside_unit_circle"] = False

    def wrong_cluster(c, mu):
        mu["cluster"] = 2

    def extra_claim(c, mu):  # a claim the checker does not check is not accepted
        c["globally_attracting"] = True

    def inverted_interval(c, mu):
        mu["re"] = [mu["re"][1] + 1.0, mu["re"][0] - 1.0]

    for edit in (widened_inside, stable_without_flags, real_with_imaginary_part, flipped_flag, wrong_cluster,
                 extra_claim, inverted_interval):
        capsys.readouterr()
        assert check(edit) == 1, edit.__name__
        assert "\n" not in capsys.readouterr().out.strip()
    capsys.readouterr()
    assert check(widened_honest) == 0
    out = capsys.readouterr().out
    assert "not claimed" in out and "asymptotically stable" not in out


@pytest.mark.slow  # uses the proved certificate of cli_cert (several seconds)
def test_checking_a_certificate_runs_no_code_it_names(cli_cert, tmp_path, capsys) -> None:
    """A certificate whose "graph" names a module that writes a marker file is checked against the graph
    on the command line: the module is never imported (the marker stays absent)."""
    _, _, cert = cli_cert
    marker = tmp_path / "marker"
    evil = tmp_path / "evil.py"
    evil.write_text(f"open({str(marker)!r}, 'w').write('ran')\n"
                    "from cpgsim.components.library import single_vdp\n"
                    "def build():\n    return single_vdp(eps=1.0, b=1.0, omega=1.0)\n")
    data = json.loads(cert.read_text())
    data["graph"] = f"{evil}:build"
    path = tmp_path / "sent.json"
    path.write_text(json.dumps(data))
    capsys.readouterr()
    assert main(["verify", "vdp", "--check-certificate", str(path)]) == 0
    assert not marker.exists()
    assert main(["verify", "--check-certificate", str(path)]) == 2  # no GRAPH: nothing is taken from the file
    assert not marker.exists()
    capsys.readouterr()
    # another graph: exit 1 naming both digests (the certified one and the graph's own)
    data["params"] = {"z.eps": 0.5, "z.b": 1.0, "z.omega": 1.0}
    path.write_text(json.dumps(data))
    assert main(["verify", "vdp", "--check-certificate", str(path)]) == 1
    msg = capsys.readouterr().out.strip()
    other, _ = system_of_graph(single_vdp(eps=0.5, b=1.0, omega=1.0))
    assert "\n" not in msg and data["tape_sha256"] in msg and Tape(other).digest() in msg
    assert not marker.exists()


@pytest.mark.parametrize("prove", [False, True])
def test_damped_linear_oscillator_gets_a_verdict_not_an_internal_error(tmp_path, capsys, prove) -> None:
    """x'' + 0.2 x' + 1.69 x = 0 (the issue's case) decays to the origin, eigenvalues -0.1 +- sqrt(1.68) i:
    exit 1 with the equilibrium verdict, with or without --prove (it once crashed in _classify)."""
    o = tmp_path / "o"
    args = ["verify", "damped-oscillator", "--set", "damper.k=-0.2", "--set", "spring.k=-1.69", "--samples", "0",
            "--no-plot", "-o", str(o)]
    assert main(args + (["--prove"] if prove else [])) == 1
    out, err = capsys.readouterr()
    assert "internal error" not in err
    assert out.splitlines()[0].endswith("no stable cycle: converges to an equilibrium")
    rep = json.loads((o / "report.json").read_text())
    assert rep["status"] == "equilibrium"
    assert all(abs(v) < 1e-6 for v in rep["equilibrium"]["x"].values())
    assert rep["equilibrium"]["stable"]
    if prove:
        assert err.strip().splitlines()[-1].startswith("not proved: no periodic orbit")


@pytest.mark.slow
def test_linear_centre_and_free_particle_get_verdicts(tmp_path, capsys) -> None:
    """x'' + 1.69 x = 0 (a centre: a family of orbits, none isolated) and x'' = 0 (every state an
    equilibrium, a structurally singular Jacobian): exit 1 with a verdict, never an internal error."""
    o = str(tmp_path / "o")
    base = ["verify", "damped-oscillator", "--samples", "0", "--no-plot", "-o", o, "--set", "damper.k=0"]
    assert main([*base, "--set", "spring.k=-1.69"]) == 1
    out, err = capsys.readouterr()
    assert "internal error" not in err and "none is isolated" in out
    assert main([*base, "--set", "spring.k=0"]) == 1
    out, err = capsys.readouterr()
    assert "internal error" not in err and "no stable cycle" in out.splitlines()[0]


@pytest.mark.slow
def test_cli_exit_codes_not_proved_and_bad_input(tmp_path, capsys) -> None:
    """Exit 1: nothing to prove (the damped oscillator converges to the origin); exit 2: bad input."""
    o = str(tmp_path / "o")
    assert main(["verify", "damped-oscillator", "--prove", "--samples", "0", "--no-plot", "-o", o]) == 1
    assert "not proved" in capsys.readouterr().err
    assert main(["verify", "vdp", "--prove", "--precision", "8", "--no-plot", "-o", o]) == 2
    assert main(["verify", "vdp", "--certificate", str(tmp_path / "c.json"), "--no-plot", "-o", o]) == 2
    junk = tmp_path / "junk.json"
    junk.write_text("{}")
    assert main(["verify", "--check-certificate", str(junk)]) == 2  # no GRAPH
    assert main(["verify", "vdp", "--check-certificate", str(junk)]) == 2
    assert main(["verify", "gait", "flat", "--prove"]) == 2  # hybrid, co-simulated: not provable
