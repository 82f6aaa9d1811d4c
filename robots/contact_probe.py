"""Friction at an edge in each engine, against Coulomb's law: a sphere pushed into a step's top corner.

Why: on the 40 mm step (Yu 2019, Sec. 6.1.1) the swing foot meets the step's corner near its apex, and
whether the corner stops it decides a reflex (docs/engines.md). This probe asks each engine the question
without the robot: a sphere (radius ``radius``, mass ``mass``, on two slide joints -- forward ``y`` and up
``z``, no rotation; no gravity) touches the edge of a box (top at ``EDGE_Z``, riser at ``y = 0``) with its
contact normal ``theta`` degrees above the horizontal, and is pushed by ``force`` newtons pointing forward
and ``phi`` degrees below the horizontal (ramped over 20 ms, then held). Both shapes have friction
``friction``.

Coulomb's law (rigid bodies): the edge's reaction must balance the push, so it points ``phi`` degrees above
the backward horizontal, ``|theta - phi|`` from the normal; the sphere stays if that is within the friction
cone, ``|theta - phi| <= atan(friction)`` (:func:`coulomb_holds`), and slides over the edge otherwise.
:func:`probe` returns how far the sphere moved in the second half of ``duration`` (mm; 0 = held).

``python -m cpgsim.robots.contact_probe`` prints the table in docs/engines.md.
"""

from __future__ import annotations

import math

import numpy as np

from cpgsim.components.core import ParameterError

EDGE_Z = 0.04  # m: the top of the box (the 40 mm step)
RAMP_S = 0.02  # s over which the push grows to its full value
HELD_MM = 0.01  # slide over the probe's last 0.1 s below which the table says "held"


def coulomb_holds(theta_deg: float, phi_deg: float, friction: float) -> bool:
    """Whether Coulomb's law holds the sphere on the edge (normal ``theta``, push ``phi`` below horizontal)."""
    return abs(theta_deg - phi_deg) <= math.degrees(math.atan(friction))


def _start(theta_deg: float, radius: float) -> tuple[float, float]:
    """The sphere centre touching the edge (y = 0, z = EDGE_Z) with its normal ``theta`` above horizontal."""
    th = math.radians(theta_deg)
    return -radius * math.cos(th), EDGE_Z + radius * math.sin(th)


def _push(k: int, dt: float, force: float, phi_deg: float) -> tuple[float, float]:
    scale = min(1.0, (k + 1) * dt / RAMP_S)
    ph = math.radians(phi_deg)
    return scale * force * math.cos(ph), -scale * force * math.sin(ph)


def probe(engine: str, theta_deg: float, phi_deg: float = 0.0, force: float = 10.0, mass: float = 0.05,
          friction: float = 1.0, radius: float = 0.01, duration: float = 0.2, time_step: float = 1e-3,
          contact=None) -> float:
    """Distance (mm) the sphere moves in the second half of ``duration`` in ``engine`` (``"dart"`` or
    ``"mujoco"``; ``contact``: MuJoCo's :class:`~cpgsim.robots.mujoco.mjcf.ContactModel`, default its defaults)."""
    if not (0.0 < theta_deg < 90.0 and 0.0 <= phi_deg < 90.0):
        raise ParameterError(f"contact probe: theta must be in (0, 90) and phi in [0, 90) degrees, got "
                             f"{theta_deg!r}, {phi_deg!r}")
    for name, value in (("force", force), ("mass", mass), ("friction", friction), ("radius", radius),
                        ("duration", duration), ("time_step", time_step)):
        if not (math.isfinite(value) and value > 0):
            raise ParameterError(f"contact probe: {name} must be > 0, got {value!r}")
    run = {"dart": _dart_path, "mujoco": _mujoco_path}.get(engine)
    if run is None:
        raise ParameterError(f"contact probe: unknown engine {engine!r} (known: dart, mujoco)")
    n = max(2, round(duration / time_step))
    path = run(theta_deg, phi_deg, force, mass, friction, radius, n, time_step, contact)
    return float(np.linalg.norm(path[-1] - path[n // 2]) * 1e3)


def _dart_path(theta, phi, force, mass, friction, radius, n, dt, contact) -> np.ndarray:
    import dartpy as dart

    if contact is not None:
        raise ParameterError("contact probe: a ContactModel is MuJoCo's; DART's contacts are rigid")
    world = dart.simulation.World()
    world.setGravity([0.0, 0.0, 0.0])
    world.setTimeStep(dt)
    world.setCollisionDetector(dart.collision.DARTCollisionDetector())
    box = dart.dynamics.Skeleton("edge")
    joint, body = box.createWeldJointAndBodyNodePair()
    shape = body.createShapeNode(dart.dynamics.BoxShape([0.2, 0.2, EDGE_Z]))
    shape.createCollisionAspect()
    shape.createDynamicsAspect().setFrictionCoeff(friction)
    pose = dart.math.Isometry3()
    pose.set_translation([0.0, 0.1, EDGE_Z / 2])
    joint.setTransformFromParentBodyNode(pose)
    world.addSkeleton(box)
    sphere = dart.dynamics.Skeleton("sphere")
    forward = dart.dynamics.PrismaticJointProperties()
    forward.mAxis = [0.0, 1.0, 0.0]
    j_y, carriage = sphere.createPrismaticJointAndBodyNodePair(None, forward)
    up = dart.dynamics.PrismaticJointProperties()
    up.mAxis = [0.0, 0.0, 1.0]
    _, ball = sphere.createPrismaticJointAndBodyNodePair(carriage, up)
    carriage.setMass(mass / 2)
    ball.setMass(mass / 2)
    node = ball.createShapeNode(dart.dynamics.SphereShape(radius))
    node.createCollisionAspect()
    node.createDynamicsAspect().setFrictionCoeff(friction)
    y0, z0 = _start(theta, radius)
    start = dart.math.Isometry3()
    start.set_translation([0.0, y0, z0])
    j_y.setTransformFromParentBodyNode(start)
    world.addSkeleton(sphere)
    path = np.empty((n, 2))
    for k in range(n):
        sphere.setForces(list(_push(k, dt, force, phi)))
        world.step()
        path[k] = sphere.getPositions()
    return path


def _mujoco_path(theta, phi, force, mass, friction, radius, n, dt, contact) -> np.ndarray:
    import mujoco

    from cpgsim.robots.mujoco.mjcf import ContactModel, geom_contact, option_element

    contact = contact or ContactModel()
    if abs(contact.timestep - dt) > 1e-15:
        contact = ContactModel(**{**contact.__dict__, "timestep": dt})
    y0, z0 = _start(theta, radius)
    solver = f'{geom_contact(contact)} friction="{friction:.17g} 0 0"'
    xml = (f'<mujoco>{option_element(contact, gravity=0.0)}<worldbody>'
           f'<geom type="box" size="0.1 0.1 {EDGE_Z / 2:.17g}" pos="0 0.1 {EDGE_Z / 2:.17g}" priority="1" {solver}/>'
           f'<body pos="0 {y0:.17g} {z0:.17g}"><joint type="slide" axis="0 1 0"/><joint type="slide" axis="0 0 1"/>'
           f'<geom type="sphere" size="{radius:.17g}" mass="{mass:.17g}" {solver}/></body></worldbody></mujoco>')
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    path = np.empty((n, 2))
    for k in range(n):
        data.qfrc_applied[:] = _push(k, dt, force, phi)
        mujoco.mj_step(model, data)
        path[k] = data.qpos
    return path


MUJOCO_OWN_DEFAULTS = {"cone": "pyramidal", "impratio": 1.0}
"""MuJoCo's own friction settings, which cpgsim's :class:`~cpgsim.robots.mujoco.mjcf.ContactModel` replaces: the probe
shows them releasing the sphere far inside Coulomb's cone (docs/engines.md)."""

NOSLIP_MUJOCO = {"noslip_iterations": 50}
"""On top of cpgsim's MuJoCo default: the noslip post-solver, which removes the last slow creep."""


def table(thetas=(20, 30, 36, 38, 40, 44, 46, 50, 60), masses=(0.05, 1.0)) -> list[dict]:
    """The probe's rows: for each mass and angle, Coulomb's verdict and each engine's slide (mm per 0.1 s)."""
    from cpgsim.robots.mujoco.mjcf import ContactModel

    settings = {"dart": ("dart", None), "mujoco (cpgsim: elliptic, impratio 100)": ("mujoco", None),
                "mujoco + noslip 50": ("mujoco", ContactModel(**NOSLIP_MUJOCO)),
                "mujoco's own defaults (pyramidal, impratio 1)": ("mujoco", ContactModel(**MUJOCO_OWN_DEFAULTS))}
    rows = []
    for mass in masses:
        for theta in thetas:
            row = {"mass_kg": mass, "theta_deg": theta, "coulomb_holds": coulomb_holds(theta, 0.0, 1.0)}
            for label, (engine, contact) in settings.items():
                row[label] = probe(engine, theta, mass=mass, contact=contact)
            rows.append(row)
    return rows


def main() -> None:
    rows = table()
    labels = [k for k in rows[0] if k not in ("mass_kg", "theta_deg", "coulomb_holds")]
    print("sphere r = 10 mm pushed forward by 10 N into a 40 mm step's edge, friction 1 (Coulomb: held up to "
          "45 deg); slide in mm over the last 0.1 s (0 = held)")
    print("| mass | normal above horizontal | Coulomb | " + " | ".join(labels) + " |")
    print("|---" * (3 + len(labels)) + "|")
    for r in rows:
        cells = ["held" if r[k] < HELD_MM else f"{r[k]:.3g}" for k in labels]
        print(f"| {r['mass_kg'] * 1000:g} g | {r['theta_deg']} deg | {'held' if r['coulomb_holds'] else 'slides'} | "
              + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
