"""The hexapod and its terrain as a MuJoCo model (MJCF text), written from the engine-neutral description.

One source of truth: :func:`mjcf` walks the link table of :func:`cpgsim.robots.description.describe_hexapod`
(the same table :func:`cpgsim.robots.dart.model.build_hexapod` walks) and the
:class:`~cpgsim.robots.terrain.Terrain` boxes, so the bodies, frames, joint axes, shapes and masses are the
DART model's:

- a free root joint carrying the body box; per leg the ``alpha``, ``beta`` and ``gamma`` hinges, in a leg
  frame with ``x`` outward (the left legs' frame is turned by pi about ``z``); box links, the tibia box
  stopping half a foot radius short of the foot sphere at the tibia's end;
- every body's mass, centre of mass and full inertia written out (``<inertial>``), from the description's
  closed forms (uniform solid box ``m/12 (b^2 + c^2)``, sphere ``2/5 m r^2``, parallel-axis sum), which
  agree with DART's ``Shape.computeInertia`` (``tests/test_mujoco.py`` checks it);
- joints unlimited, as in DART (the servos hold them); the servos are ``general`` actuators whose force
  is DART's servo law (:class:`cpgsim.robots.mujoco.plant.MujocoHexapod` sets the gains);
- terrain boxes as static world geoms. Only robot-terrain pairs collide (``contype``/``conaffinity``),
  as in DART, where a skeleton does not collide with itself.

Friction: DART takes the smaller of two touching shapes' coefficients, MuJoCo the larger unless one geom
has a higher ``priority``; the terrain geoms get priority 1 and ``min(robot, terrain)`` friction, so the
pair's coefficient is DART's. Contact parameters (:class:`ContactModel`) are documented in docs/engines.md.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass

from cpgsim.components.core import ParameterError
from cpgsim.components.geometry import LEG_NAMES, RobotGeometry
from cpgsim.robots.description import GRAVITY, AnkleSpring, BodyMass, LinkSizes, LinkSpec, describe_hexapod
from cpgsim.robots.terrain import Terrain

CONES = ("pyramidal", "elliptic")
CONDIMS = (1, 3, 4, 6)


@dataclass(frozen=True)
class ContactModel:
    """MuJoCo's contact and integration settings (docs/engines.md gives the measurements behind them).

    - ``timestep``: 1 ms, DART's world step: one ``mj_step`` per control step (0.5 ms changed no
      reflex of the 40 mm step and costs twice the time);
    - ``solref``: ``(timeconst, dampratio)`` of the contact's spring-damper: 5 ms, critically damped.
      MuJoCo needs ``timeconst >= 2 timestep``; its 20 ms default lets feet sink and bounce slowly, 5 ms
      holds the standing robot with 0.09 mm of penetration and no bounce;
    - ``solimp``: impedance ``(d0, dwidth, width)``: stiffening from 0.9 to 0.99 over 1 mm of penetration;
    - ``condim``: 3 (normal + two tangential directions: Coulomb friction, no torsional/rolling friction,
      as DART's contacts);
    - ``cone``: ``'elliptic'``, the true Coulomb cone, and ``impratio``: 100 (frictional constraints 100
      times harder than normal ones). MuJoCo's own defaults (pyramidal, impratio 1) make friction a soft
      constraint: at a step's corner a 50 g sphere pushed 20 degrees off the contact normal slides away, where
      Coulomb's law with mu = 1 holds it up to 45 degrees (``python -m cpgsim.robots.contact_probe``); with
      these two settings MuJoCo holds to 44 and releases at 46 degrees. On the robot the soft friction let
      swing feet step onto the 40 mm step without the elevator reflex where a Coulomb foot is arrested
      (over 41 step positions from 0.30 to 0.50 m: R1, R2, R3 and a success at 3 with MuJoCo's defaults, 34
      with these, 39 in DART; ``examples/08_step_position_map.py``, docs/engines.md). They cost about 13 %
      per step (the whole ``step`` run 28.0x -> 23.9x real time, interleaved); a pyramidal cone with
      impratio 100 holds too but is slower (21.9x: the solver needs more iterations) and gave R1, R2, R3
      at 6 of 21 positions 10 mm apart, the elliptic cone at 18;
    - ``noslip_iterations``: 0 (MuJoCo's default: off). Above 0, MuJoCo's noslip post-solver removes the
      slow creep that is left under a sustained tangential load (about 0.03 mm per 0.1 s for a 50 g sphere
      inside the cone with the settings above; 50 iterations: none) at about 6 % more per step.

    Scenario files set any of these in ``[robot.mujoco]`` (``--set robot.mujoco.impratio=10``); the values
    are checked here (``ParameterError`` naming the field) and written into the MJCF by :func:`mjcf`.
    """

    timestep: float = 1e-3
    solref: tuple[float, float] = (0.005, 1.0)
    solimp: tuple[float, float, float] = (0.9, 0.99, 0.001)
    condim: int = 3
    cone: str = "elliptic"
    impratio: float = 100.0
    noslip_iterations: int = 0

    def __post_init__(self) -> None:
        def number(name: str, value: object) -> float:
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ParameterError(f"ContactModel.{name} must be a finite number, got {value!r}")
            return float(value)

        def numbers(name: str, value: object, n: int) -> tuple[float, ...]:
            if not isinstance(value, (tuple, list)) or len(value) != n:
                raise ParameterError(f"ContactModel.{name} must be {n} numbers, got {_plain(value)}")
            return tuple(number(f"{name}[{k}]", v) for k, v in enumerate(value))

        timestep = number("timestep", self.timestep)
        if timestep <= 0:
            raise ParameterError(f"ContactModel.timestep must be > 0 s, got {timestep:g}")
        timeconst, dampratio = numbers("solref", self.solref, 2)
        if timeconst <= 0 or dampratio <= 0:
            raise ParameterError(f"ContactModel.solref = (time constant, damping ratio) must both be > 0 "
                                 f"(MuJoCo reads negative values as stiffness and damping), got {_plain(self.solref)}")
        d0, dwidth, width = numbers("solimp", self.solimp, 3)
        if not (0 < d0 < 1 and 0 < dwidth < 1 and width > 0):
            raise ParameterError(f"ContactModel.solimp = (d0, dwidth, width) needs 0 < d0, dwidth < 1 and "
                                 f"width > 0 m, got {_plain(self.solimp)}")
        if self.condim not in CONDIMS or isinstance(self.condim, bool):
            raise ParameterError(f"ContactModel.condim must be one of {', '.join(map(str, CONDIMS))}, "
                                 f"got {self.condim!r}")
        if self.cone not in CONES:
            raise ParameterError(f"ContactModel.cone must be one of {', '.join(CONES)}, got {self.cone!r}")
        if number("impratio", self.impratio) <= 0:
            raise ParameterError(f"ContactModel.impratio (frictional over normal impedance) must be > 0, "
                                 f"got {self.impratio!r}")
        if isinstance(self.noslip_iterations, bool) or not isinstance(self.noslip_iterations, int) \
                or self.noslip_iterations < 0:
            raise ParameterError(f"ContactModel.noslip_iterations must be an integer >= 0, "
                                 f"got {self.noslip_iterations!r}")
        object.__setattr__(self, "timestep", timestep)
        object.__setattr__(self, "solref", (timeconst, dampratio))
        object.__setattr__(self, "solimp", (d0, dwidth, width))
        object.__setattr__(self, "impratio", float(self.impratio))

    @classmethod
    def fields(cls) -> tuple[str, ...]:
        """The settable fields, in declaration order."""
        return tuple(f.name for f in dataclasses.fields(cls))

    def describe(self) -> dict[str, object]:
        """The settings as plain values (JSON, summaries)."""
        return {k: list(v) if isinstance(v, tuple) else v for k, v in dataclasses.asdict(self).items()}


def option_element(contact: ContactModel, gravity: float = GRAVITY) -> str:
    """The MJCF ``<option>`` of ``contact`` (the integrator is ``implicitfast``: the servos' damping implicit)."""
    return (f'<option timestep="{contact.timestep:.17g}" gravity="0 0 {-gravity:.17g}" integrator="implicitfast" '
            f'cone="{contact.cone}" impratio="{contact.impratio:.17g}" '
            f'noslip_iterations="{contact.noslip_iterations}"/>')


def geom_contact(contact: ContactModel) -> str:
    """A geom's contact attributes (``condim``, ``solref``, ``solimp``) of ``contact``."""
    return f'condim="{contact.condim}" solref="{_v(contact.solref)}" solimp="{_v(contact.solimp)}"'


def _plain(value: object) -> str:
    """``value`` as a scenario file writes it (a tuple as a list)."""
    return repr(list(value)) if isinstance(value, tuple) else repr(value)


def _v(values: Sequence[float]) -> str:
    return " ".join(f"{float(x):.17g}" for x in values)


def _inertial(bm: BodyMass) -> str:
    I = bm.inertia  # noqa: E741
    full = (I[0, 0], I[1, 1], I[2, 2], I[0, 1], I[0, 2], I[1, 2])
    return f'<inertial pos="{_v(bm.com)}" mass="{bm.mass:.17g}" fullinertia="{_v(full)}"/>'


ROBOT_COLLISION = 'contype="1" conaffinity="0"'
TERRAIN_COLLISION = 'contype="0" conaffinity="1" priority="1"'


def mass_properties(geometry: RobotGeometry, links: LinkSizes | None = None) -> dict[str, BodyMass]:
    """Mass, COM and inertia of every body (``body``, ``L1_coxa``, ``L1_femur``, ``L1_tibia``, ...)."""
    return describe_hexapod(geometry, links).mass_properties()


def _link_lines(link: LinkSpec, children: dict[str, list[LinkSpec]], rgeom: str, depth: int) -> list[str]:
    """The ``<body>`` element of ``link`` and, nested, its children's."""
    pad = "  " * depth
    if link.parent is None:
        lines = [f'{pad}<body name="{link.name}" pos="0 0 0">', f'{pad}  <freejoint name="root"/>']
    else:
        quat = ' quat="0 0 0 1"' if link.turned else (' quat="1 0 0 0"' if link.joint.endswith("_alpha") else "")
        lines = [f'{pad}<body name="{link.name}" pos="{_v(link.origin)}"{quat}>']
        if link.kind == "slide":  # the compliant ankle (AnkleSpring): a joint spring-damper, rest length 0
            lines.append(f'{pad}  <joint name="{link.joint}" type="slide" axis="{_axis(link.axis)}" '
                         f'stiffness="{link.spring.stiffness:.17g}" damping="{link.spring.damping:.17g}" '
                         f'springref="0"/>')
        else:
            lines.append(f'{pad}  <joint name="{link.joint}" type="hinge" axis="{_axis(link.axis)}"/>')
    lines.append(f'{pad}  {_inertial(link.mass_properties())}')
    for spec in link.shapes:
        if spec.kind == "sphere":
            lines.append(f'{pad}  <geom name="{spec.name}" type="sphere" size="{spec.size[0]:.17g}" '
                         f'pos="{_v(spec.offset)}" {rgeom}/>')
        elif link.parent is None:
            lines.append(f'{pad}  <geom name="{spec.name}" type="box" size="{_v(tuple(x / 2 for x in spec.size))}" '
                         f'{rgeom}/>')
        else:
            lines.append(f'{pad}  <geom name="{spec.name}" type="box" size="{_v(tuple(x / 2 for x in spec.size))}" '
                         f'pos="{_v(spec.offset)}" {rgeom}/>')
    for child in children.get(link.name, []):
        lines += _link_lines(child, children, rgeom, depth + 1)
    lines.append(f'{pad}</body>')
    return lines


def _axis(axis: tuple[float, float, float]) -> str:
    return " ".join(f"{a:g}" for a in axis)


def mjcf(geometry: RobotGeometry, terrain: Terrain, friction: float = 1.0,
         contact: ContactModel | None = None, links: LinkSizes | None = None,
         ankle: AnkleSpring | None = None) -> str:
    """The MJCF document of the hexapod on ``terrain`` (body at the world origin, joints at 0).

    Actuators ``{leg}_{joint}_servo`` (one per hinge, leg-major) are ``general`` with unit gain and zero
    bias; the plant writes the servo gains into ``actuator_gainprm``/``actuator_biasprm``. ``ankle``: each
    foot on a sprung slide joint ``{leg}_ankle`` (:class:`~cpgsim.robots.description.AnkleSpring`), after the
    leg's three hinges in ``qpos``.
    """
    contact = contact or ContactModel()
    description = describe_hexapod(geometry, links, ankle)
    geom_common = geom_contact(contact)
    rgeom = f'{ROBOT_COLLISION} friction="{friction:.17g} 0 0" {geom_common}'
    lines = [
        f'<mujoco model="{geometry.name}">',
        '  <compiler angle="radian" autolimits="true" inertiafromgeom="false"/>',
        f'  {option_element(contact)}',
        '  <size memory="4M"/>',
        '  <worldbody>',
    ]
    ground_mu = min(friction, terrain.friction)
    for k, b in enumerate(terrain.boxes):
        centre, size, angle = b.pose()
        turn = f'euler="{angle:.17g} 0 0" ' if angle else ""
        lines.append(f'    <geom name="ground_{k}" type="box" size="{_v(tuple(size / 2))}" pos="{_v(tuple(centre))}" '
                     f'{turn}{TERRAIN_COLLISION} friction="{ground_mu:.17g} 0 0" {geom_common}/>')
    children: dict[str, list[LinkSpec]] = {}
    for link in description.links[1:]:
        children.setdefault(link.parent, []).append(link)
    lines += _link_lines(description.links[0], children, rgeom, 2)
    lines += ['  </worldbody>', '  <actuator>']
    for name in LEG_NAMES:
        for j in ("alpha", "beta", "gamma"):
            lines.append(f'    <general name="{name}_{j}_servo" joint="{name}_{j}" gainprm="1" biasprm="0 0 0" '
                         f'biastype="affine"/>')
    lines += ['  </actuator>', '</mujoco>']
    return "\n".join(lines) + "\n"
