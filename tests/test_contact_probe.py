"""Friction at an edge against Coulomb's law (``cpgsim.robots.contact_probe``): a sphere pushed into a step's
corner is held exactly when the push lies within the friction cone about the contact normal
(``|theta - phi| <= atan(mu)``, 45 degrees for mu = 1). Where an engine departs from the law, the test pins
the departure docs/engines.md reports, so the page goes stale loudly if an engine release changes it."""

from __future__ import annotations

import pytest

from cpgsim.components.core import ParameterError
from cpgsim.robots.contact_probe import MUJOCO_OWN_DEFAULTS, NOSLIP_MUJOCO, coulomb_holds, probe

HELD_MM = 0.01  # slide over 0.1 s below which the sphere counts as held
SLID_MM = 10.0  # ... and above which it has clearly slid (a sliding sphere moves metres in 0.1 s)


def test_coulomb_criterion():
    assert coulomb_holds(30, 0, 1.0) and coulomb_holds(45, 0, 1.0) and not coulomb_holds(46, 0, 1.0)
    assert coulomb_holds(60, 40, 1.0) and not coulomb_holds(60, 10, 1.0)  # a downward push steepens the cone
    assert coulomb_holds(25, 0, 0.5) and not coulomb_holds(30, 0, 0.5)  # atan(0.5) = 26.6 deg


@pytest.mark.parametrize("theta, phi", [(20, 0), (30, 0), (36, 0), (60, 40), (70, 40)])
def test_dart_holds_where_coulomb_holds_below_37_degrees_from_the_push(theta, phi):
    assert coulomb_holds(theta, phi, 1.0)
    assert probe("dart", theta, phi) < HELD_MM


@pytest.mark.parametrize("theta, phi", [(50, 0), (60, 0), (70, 10)])
def test_dart_slides_where_coulomb_slides(theta, phi):
    assert not coulomb_holds(theta, phi, 1.0)
    assert probe("dart", theta, phi) > SLID_MM


def test_dart_lets_go_before_the_cone_edge():
    """DART's departure (docs/engines.md): pushed horizontally, the sphere slides from 38 degrees on, where
    Coulomb's mu = 1 holds it to 45 (DART holds like mu = tan(37 deg) = 0.75 there; pushed 30-40 degrees
    downward it holds to 40 degrees off the normal and lets go by 44)."""
    assert coulomb_holds(40, 0, 1.0) and probe("dart", 40) > SLID_MM
    assert probe("dart", 40, mass=1.0) > SLID_MM


CREEP_MM = 0.05  # MuJoCo's hard friction without noslip: a slow creep (0.01-0.03 mm per 0.1 s at 50 g) is left


@pytest.mark.parametrize("theta, held", [(20, True), (30, True), (44, True), (46, False), (60, False)])
def test_mujoco_default_follows_coulomb_to_one_degree(theta, held):
    """cpgsim's MuJoCo default (elliptic cone, impratio 100): held to 44 degrees, released at 46; with the
    noslip post-solver the creep that is left goes too."""
    pytest.importorskip("mujoco", reason="the mujoco package is not installed (pip install 'cpgsim[mujoco]')")
    from cpgsim.robots.mujoco.mjcf import ContactModel

    assert coulomb_holds(theta, 0, 1.0) is held
    slide = probe("mujoco", theta)
    assert slide < CREEP_MM if held else slide > SLID_MM
    noslip = probe("mujoco", theta, contact=ContactModel(**NOSLIP_MUJOCO))
    assert noslip < HELD_MM if held else noslip > SLID_MM


def test_mujoco_own_default_friction_slides_inside_the_cone():
    """MuJoCo's own defaults (pyramidal cone, impratio 1), which cpgsim replaces: friction is a soft
    constraint, so a light sphere slides away at 20 and 30 degrees, well inside the cone, and a 1 kg one
    creeps (docs/engines.md)."""
    pytest.importorskip("mujoco", reason="the mujoco package is not installed (pip install 'cpgsim[mujoco]')")
    from cpgsim.robots.mujoco.mjcf import ContactModel

    soft = ContactModel(**MUJOCO_OWN_DEFAULTS)
    assert coulomb_holds(20, 0, 1.0) and coulomb_holds(30, 0, 1.0)
    assert probe("mujoco", 20, contact=soft) > SLID_MM and probe("mujoco", 30, contact=soft) > SLID_MM
    assert 0.1 < probe("mujoco", 30, mass=1.0, contact=soft) < SLID_MM


@pytest.mark.parametrize("kwargs, message", [
    ({"engine": "bullet", "theta_deg": 30}, "unknown engine 'bullet'"),
    ({"engine": "dart", "theta_deg": 95}, "theta must be in"),
    ({"engine": "dart", "theta_deg": 30, "mass": 0.0}, "mass must be > 0"),
    ({"engine": "dart", "theta_deg": 30, "contact": object()}, "ContactModel is MuJoCo's"),
])
def test_probe_rejects_bad_input(kwargs, message):
    with pytest.raises(ParameterError, match=message):
        probe(**kwargs)
