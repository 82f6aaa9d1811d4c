"""The hexapod in DART as a co-simulation block (the plant of the 1 kHz control loop).

The ports and parameters are every engine's (:mod:`cpgsim.robots.ports`); what all plants share is in
:class:`~cpgsim.robots.plant_base.HexapodPlant`. This module is DART's part.

Servos. Each joint is a DART joint spring and damper, ``tau = -kp (q - q_target) - kd qd``,
integrated implicitly by DART: explicit Python PD torques at 1 ms were measured to go unstable on
light links from ``kp >= 100`` while this scheme stayed stable up to ``kp = 1000``. The spring's
rest position stays at 0 and the target enters as the joint force ``kp q_target`` (DART's spring
force is ``-kp (q + h qd - q_rest)``, so this is the same law; one ``setForces`` call per step
instead of 18 ``setRestPosition`` calls). With ``velocity_ff = 1`` the force gains
``kd * dq_target/dt`` so the damper acts on the velocity *error* (removes the tracking lag
``kd/kp * qd`` of a moving target); the target velocity is a backward difference of the inputs,
so a jump of the target gives a one-step kick -- keep it off for discontinuous targets (default).
Default gains scale with the robot (:func:`default_gains`). Parameters apply at :meth:`setup`, or
at once when :meth:`set` is called on a set-up plant.

Contacts. After every world step the contacts of the last collision result are summed per leg;
each contact's ``force`` acts on ``collisionObject1`` (the sign is flipped when the robot's shape
is object 2; the order depends on the detector). With ``sense_shank`` (default) a contact on the
tibia box counts as a toe force too (a leg hitting a step edge with its shank is sensed like a
toe contact). Contact forces are impulses divided by the step, so touchdowns spike; over a macro
step ``dt`` longer than the world step the force is averaged over the sub-steps.

Cost (``benchmarks/bench_run.py``, docs/performance.md, "The DART loop"). A 1 kHz closed loop steps the
plant 1000 times per simulated second. With a C compiler, ``do_step`` is one C call
(:mod:`cpgsim.robots.dart.native`: ``setForces``, ``World::step``, the contact sums, the state read and
the readout, through the DART symbols dartpy exports), and with a compiled controller and no other
co-simulation block the whole loop runs in C, chunks of 100 macro steps per call
(:meth:`DartHexapod.fused_loop`, :mod:`cpgsim.robots.dart.fused`). The Python loop below stays the
reference and the fallback (``native=False``, pushes, several world steps per macro step; the C
step is checked against it over each set-up's first steps): one ``setForces`` for the servos; collision
objects identified by their (kept-alive) wrappers' ``id()`` after the first sight (the terrain is usually
object 1, so object 2 is looked at first); every output (foot centres, body-frame toe forces,
roll/pitch/yaw) from one compiled CasADi function (:mod:`cpgsim.robots.readout`) on the skeleton's
positions and velocities.
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import dartpy as dart
import numpy as np

from cpgsim.components.core import ModelError, ParameterError
from cpgsim.components.geometry import YU_SIM, RobotGeometry
from cpgsim.harness.cosim.contracts import FusedLoopBlock, FusedRequest, ResumableBlock
from cpgsim.harness.native import NativeUnavailable
from cpgsim.robots.dart import native as dart_native
from cpgsim.robots.dart.ground import add_terrain
from cpgsim.robots.dart.model import HexapodModel, build_hexapod
from cpgsim.robots.description import CONTACT_OTHER, GRAVITY, AnkleSpring, describe_hexapod
from cpgsim.robots.disturbance import Push
from cpgsim.robots.plant_base import HexapodPlant
from cpgsim.robots.readout import StateLayout
from cpgsim.robots.terrain import Terrain

_free_to_transform = dart.dynamics.FreeJoint.convertToTransform
DETECTORS = {
    "dart": dart.collision.DARTCollisionDetector,
    "fcl": dart.collision.FCLCollisionDetector,
    "bullet": dart.collision.BulletCollisionDetector,
    "ode": dart.collision.OdeCollisionDetector,
}


class DartHexapod(HexapodPlant, ResumableBlock, FusedLoopBlock):
    """The hexapod on a terrain in a DART world, stepped by the co-simulation master.

    Constructor arguments: those of :class:`~cpgsim.robots.plant_base.HexapodPlant` (``geometry`` default
    ``YU_SIM``), and

    - ``detector``: ``'dart'`` (default: exact for spheres and boxes, the fastest measured),
      ``'fcl'``, ``'bullet'`` or ``'ode'``;
    - ``time_step``: the DART world step (s, default 1 ms); ``do_step``'s ``dt`` must be a
      multiple of it;
    - ``native``: step the world through the C step (:mod:`cpgsim.robots.dart.native`) when it can be built
      (``True``, default), or always in Python (``False``: the reference the C step is checked against); a
      scenario sets it as ``robot.native``.

    Amputated legs' shapes are taken out of the world's collision group after the world is built, before
    the settle phase.
    """

    engine = "dart"
    READOUT_ROOT = "rotvec"

    def __init__(self, name: str = "robot", geometry: RobotGeometry = YU_SIM, terrain: Terrain | None = None,
                 q0: Sequence[float] | None = None, body_height: float | None = None, detector: str = "dart",
                 time_step: float = 1e-3, sense_shank: bool = True, settle: float = 0.0,
                 disturbances: Sequence[Push | Mapping] | None = None, amputated: Sequence[int] = (),
                 native: bool = True, ankle: AnkleSpring | Mapping | None = None, **params: float) -> None:
        if detector not in DETECTORS:
            raise ParameterError(f"unknown collision detector {detector!r} (known: {', '.join(DETECTORS)})")
        if not (math.isfinite(time_step) and time_step > 0):
            raise ParameterError(f"time_step must be > 0, got {time_step!r}")
        self.detector = detector
        self.native = bool(native)
        self.time_step = float(time_step)
        self.world: dart.simulation.World | None = None
        self.model: HexapodModel | None = None
        self.native_step: dart_native.NativeDartStep | None = None
        super().__init__(name, geometry, terrain, q0, body_height, sense_shank, settle, disturbances, amputated,
                         ankle=ankle, **params)

    @property
    def is_set_up(self) -> bool:
        return self.world is not None

    def state_layout(self) -> StateLayout:
        """DART's generalized coordinates: the free joint's six, the 18 joints, then the six ankle slides."""
        if self.ankle is None:
            return StateLayout.rigid(self.READOUT_ROOT)
        return StateLayout(30, 30, tuple(range(6, 24)), tuple(range(6, 24)), tuple(range(24, 30)))

    # -- parameters -------------------------------------------------------------------------------
    def set(self, **values: float) -> DartHexapod:
        """Set parameters (validated); on a set-up plant, gains and friction apply from the next step."""
        super().set(**values)
        if self.model is not None:
            v = self.values
            for j in self.model.joints:
                j.setSpringStiffness(0, v["kp"])
                j.setDampingCoefficient(0, v["kd"])
            self._target_changed = True  # the servo forces scale with kp
            for bodies in [[self.model.body], *self.model.link_bodies]:
                for bn in bodies:
                    for sn in bn.getShapeNodes():
                        sn.getDynamicsAspect().setFrictionCoeff(v["friction"])
        return self

    # -- lifecycle --------------------------------------------------------------------------------
    def setup(self, t0: float) -> None:
        """Build the world (terrain + robot), place the robot, set the servos; clock at ``t0``."""
        self.terminate()
        v = self.values
        world = dart.simulation.World()
        world.setTimeStep(self.time_step)
        world.setGravity(np.array([0.0, 0.0, -GRAVITY]))
        world.setCollisionDetector(DETECTORS[self.detector]())
        opts = world.getDeactivationOptions()  # dartpy 6.20 puts resting bodies to sleep (contacts read 0)
        opts.mEnabled = False
        world.setDeactivationOptions(opts)
        self._terrain_skel = add_terrain(world, self.terrain)

        if self.ankle is not None:
            check_explicit_ankle(self.ankle, self.geometry.leg.foot_mass, self.time_step)
        model = build_hexapod(self.geometry, friction=v["friction"], ankle=self.ankle)
        model.set_joint_angles(self.q0)
        model.set_body_pose([0.0, 0.0, 0.0])
        z = self.body_height if self.body_height is not None else self._touching_height(model.foot_positions())
        model.set_body_pose([0.0, 0.0, z])
        for j in model.joints:  # rest at 0: the target enters as the force kp * q_target (see do_step)
            j.setSpringStiffness(0, v["kp"])
            j.setDampingCoefficient(0, v["kd"])
            j.setRestPosition(0, 0.0)
        world.addSkeleton(model.skeleton)
        self.world, self.model = world, model

        # collision shape -> contact code (robots.description: a leg index for a sensed toe, CONTACT_LINK + leg,
        # CONTACT_BODY). Shapes are identified by object identity: pybind11 hands back the registered wrapper of
        # a shape we keep alive, so id() of collisionObject.getShape() is a cheap, stable key.
        self._shapes = []  # keep the wrappers alive so id() stays valid
        self._shape_leg: dict[int, int] = {}
        codes = {spec.name: spec.contact_code(self.sense_shank)
                 for spec in describe_hexapod(self.geometry, ankle=self.ankle).shapes()}
        for i, foot in enumerate(model.feet):
            self._register(foot.getShape(), i)
        for bodies in model.link_bodies:
            for bn in bodies:
                for sn in bn.getShapeNodes():
                    if sn.getName().endswith("_foot"):
                        continue
                    self._register(sn.getShape(), codes[sn.getName()])
        for sn in model.body.getShapeNodes():
            self._register(sn.getShape(), codes[sn.getName()])

        # collision object wrapper -> code (filled on first sight; the wrappers are kept alive so their id()
        # stays valid): saves two getShape() calls per contact and step
        self._objects: list = []
        self._object_code: dict[int, int] = {}
        self._skel = model.skeleton
        self._reset_readings()
        self._forces = np.zeros(model.skeleton.getNumDofs())
        self._bind_readout()
        self._bind_native()
        self._amputate()
        resume = self._take_resume(t0)
        if resume is not None:
            self.restore(resume)
            return
        self._settle(self.settle)
        world.setTime(float(t0))
        self._t = float(t0)
        self.update_outputs()

    def _amputate(self) -> None:
        """The amputated legs' shapes out of the collision world (links and masses stay)."""
        if not self.amputated:
            return
        group = self.world.getConstraintSolver().getCollisionGroup()
        for i in self.amputated:
            for body in self.model.link_bodies[i]:
                for node in body.getShapeNodes():
                    group.removeShapeFrame(node)
                    node.removeCollisionAspect()

    # -- exact state ------------------------------------------------------------------------------
    def snapshot(self) -> PlantSnapshot:
        """Everything the next steps depend on: the skeleton's generalized positions and velocities, the
        clock, the servo targets (and the previous ones, for ``velocity_ff``) and the contact readings of
        the last step (the outputs at this time). DART keeps no other state between world steps that
        changes the result (collision detection and the LCP contact solve start afresh every step: the
        tests check ``restore`` -> run against the uninterrupted run bit for bit)."""
        if self.world is None:
            raise ModelError(f"{self.name}: snapshot before setup")
        return PlantSnapshot(
            t=self._t, positions=np.array(self._skel.getPositions()), velocities=np.array(self._skel.getVelocities()),
            q_target=self._q_target.copy(), q_target_prev=np.array(self._q_target_prev, dtype=float),
            target_changed=self._target_changed, ff_active=self._ff_active, forces=self._forces.copy(),
            force_world=self._force_world.copy(), body_contact=self._body_contact,
            link_contact=self._link_contact.copy(), n_steps=self._n_steps)

    def restore(self, snap: PlantSnapshot) -> None:
        """Put a set-up plant into the state ``snap`` (see :meth:`snapshot`)."""
        if self.world is None:
            raise ModelError(f"{self.name}: restore before setup")
        n = self._skel.getNumDofs()
        if snap.positions.shape != (n,) or snap.velocities.shape != (n,):
            raise ModelError(f"{self.name}: a snapshot of {snap.positions.size} dofs does not fit {n} dofs")
        self._skel.setPositions(snap.positions.copy())
        self._skel.setVelocities(snap.velocities.copy())
        self._skel.resetAccelerations()
        self._skel.clearExternalForces()
        self._skel.clearConstraintImpulses()
        self.world.setTime(float(snap.t))
        self._t = float(snap.t)
        self._q_target = snap.q_target.copy()
        self._q_target_prev = snap.q_target_prev.copy()
        self._target_changed = snap.target_changed
        self._ff_active = snap.ff_active
        self._forces[:] = snap.forces
        self._force_world[:] = snap.force_world
        self._body_contact = snap.body_contact
        self._link_contact[:] = snap.link_contact
        self._n_steps = snap.n_steps
        self.update_outputs()

    def _bind_native(self) -> None:
        """The C step (:mod:`cpgsim.robots.dart.native`) on this plant's world and buffers, when it works."""
        self.native_step = None
        if not self.native or self.ankle is not None:  # the C step applies no ankle forces: Python steps them
            return
        readout = self.compiled_readout.c_entry() if self.compiled_readout is not None else None
        try:
            self.native_step = dart_native.NativeDartStep(
                self.world, self._skel, self._forces, self._force_world, self._link_contact, self._pos, self._vel,
                self._contact, readout)
        except NativeUnavailable as exc:
            self._drop_native(exc, stacklevel=4)
        if self.native_step is not None and readout is None:
            step = self.native_step.step

            def step_and_readout() -> int:  # the readout in CasADi's VM (no C compiler for it)
                rc = step()
                if rc in (0, 2):
                    self.readout()
                return rc
            self.native_step.step = step_and_readout

    def check_native_step(self) -> None:
        """Compare the C step's contact sums and state with the Python readout of the same step (bit for bit);
        on any difference keep Python from now on (the Python values are in place either way)."""
        native = self.native_step
        native.checks_left -= 1
        c_values = (self._force_world.tobytes(), self._link_contact.tobytes(), self._body_contact,
                    self._pos.tobytes(), self._vel.tobytes())
        self.read_contacts()
        self.update_outputs()
        if c_values != (self._force_world.tobytes(), self._link_contact.tobytes(), self._body_contact,
                        self._pos.tobytes(), self._vel.tobytes()):
            self._drop_native("the C step's contact readout differs from the bindings'", stacklevel=4)

    def _drop_native(self, reason: object, stacklevel: int) -> None:
        """Step DART in Python from now on (the C step is closed), saying why."""
        warnings.warn(f"{self.name}: DART's step stays in Python ({reason})", RuntimeWarning, stacklevel=stacklevel)
        if self.native_step is not None:
            self.native_step.close()
        self.native_step = None

    def _step_native(self) -> None:
        """One world step through the C step: ``setForces``, ``world.step()``, contact sums, outputs."""
        native = self.native_step
        rc = native.step()
        if rc == 1:  # a collision object met for the first time: this step's contacts in Python
            self.read_contacts()
            self.update_outputs()
        elif rc < 0:
            raise RuntimeError("compiled function of the plant readout reported an evaluation error")
        else:
            self._body_contact = rc == 2
            if native.checks_left:
                self.check_native_step()

    def _register(self, shape: dart.dynamics.Shape, code: int) -> None:
        self._shapes.append(shape)
        self._shape_leg[id(shape)] = code

    def terminate(self) -> None:
        """Keep the final state (:attr:`last_snapshot`), then drop the world (contacts of a removed world must
        not be touched again: reading them segfaulted)."""
        if self.world is not None:
            try:
                self.last_snapshot = self.snapshot()
            except (AttributeError, ModelError):  # a setup that failed half-way: nothing to continue from
                self.last_snapshot = None
        if self.native_step is not None:
            self.native_step.close()  # holds the world's C++ address
        self.native_step = None
        self.world = None
        self.model = None
        self._shapes = []
        self._shape_leg = {}
        self._objects = []
        self._object_code = {}

    # -- stepping (the macro step, averaging and servo law: HexapodPlant) ------------------------------
    def _native_steps(self, n: int, t: float | None = None) -> bool:
        """One world step through the C step (which also runs the readout); it takes no longer macro steps and
        no pushes (those steps run in Python)."""
        if n != 1 or (t is not None and self.pushes):
            return False
        self._step_native()
        return True

    def _world_step(self, pushes: Sequence[Push]) -> None:
        """``setForces`` (``world.step()`` clears them, and the external forces too), the pushes as external
        forces on the body, ``world.step()``."""
        if self.ankle is not None:  # the compliant ankles' spring-damper, explicit (robots.dart.model.build_hexapod)
            k, c = self.ankle.stiffness, self.ankle.damping
            self._forces[24:30] = -k * self._skel.getPositions()[24:30] - c * self._skel.getVelocities()[24:30]
        self._skel.setForces(self._forces)
        for push in pushes:
            self.model.body.addExtForce(np.asarray(push.force_N), np.asarray(push.point_m), False, True)
        self.world.step()

    def _apply_servo(self, q_target: np.ndarray, velocity: np.ndarray | None) -> None:
        """Joint forces ``kp q_target`` (+ ``kd dq_target/dt`` with ``velocity_ff``).

        DART's joint spring, at rest position 0, adds ``-kp (q + h qd) - kd qd`` implicitly, so the total
        is the servo law ``-kp (q + h qd - q_target) - kd qd`` of a spring whose rest position is the
        target -- one ``setForces`` call instead of 18 ``setRestPosition`` calls.
        """
        v = self.values
        legs = self._forces[6:24]  # the 18 servoed joints (a compliant ankle's slides follow them)
        np.multiply(q_target, v["kp"], out=legs)
        if velocity is not None:
            legs += v["kd"] * velocity

    def _object_code_of(self, obj) -> int:
        """Code of a collision object (leg index, ``CONTACT_LINK + leg``, ``CONTACT_BODY`` or
        ``CONTACT_OTHER``), registered on first sight (its wrapper is kept alive so ``id()`` identifies it
        from then on)."""
        code = self._shape_leg.get(id(obj.getShape()), CONTACT_OTHER)
        self._objects.append(obj)
        self._object_code[id(obj)] = code
        if self.native_step is not None:
            try:
                self.native_step.register(obj, code)
            except NativeUnavailable as exc:
                self._drop_native(exc, stacklevel=3)
        return code

    def _robot_contacts(self):
        """The last collision result's contacts with a robot shape. ``c.force`` acts on object 1; the DART
        detector lists the terrain first, so object 2 is looked at first."""
        lookup = self._object_code.get
        for c in self.world.getLastCollisionResult().getContacts():
            o2 = c.collisionObject2
            code = lookup(id(o2))
            if code is None:
                code = self._object_code_of(o2)
            if code != CONTACT_OTHER:
                yield code, -1.0, c
                continue
            o1 = c.collisionObject1
            code = lookup(id(o1))
            if code is None:
                code = self._object_code_of(o1)
            if code != CONTACT_OTHER:
                yield code, 1.0, c

    @staticmethod
    def _contact_force(contact) -> list[float]:
        return contact.force.tolist()

    def _read_state(self) -> None:
        skel = self._skel
        self._pos[:] = skel.getPositions()
        self._vel[:] = skel.getVelocities()

    # -- the closed loop in C --------------------------------------------------------------------
    def fused_loop(self, request: FusedRequest):
        """A :class:`~cpgsim.robots.dart.fused.FusedLoop` running this plant with the controller's bound
        compiled step in one C loop (the master's fast path, :mod:`cpgsim.harness.cosim.fused`), or None when this
        set-up cannot: no C step or compiled readout, ``velocity_ff`` on, pushes, more than one world step per
        macro step, an input that is not ``q_target``."""
        if self.native_step is None or self._fused_refusal(request) or self.steps_for(request.dt) != 1:
            return None
        indices = request.indices(self.output_slices, "q_target", 18)
        if indices is None:
            return None
        from cpgsim.robots.dart.fused import FusedLoop

        return FusedLoop(self, self.native_step, request, *indices)

    # -- the fall test ----------------------------------------------------------------------------
    def _state_finite(self) -> bool:
        return bool(np.all(np.isfinite(self._skel.getPositions())))

    def _body_rotation(self) -> np.ndarray:
        return _free_to_transform(self._skel.getPositions()[:6]).matrix()[:3, :3]


@dataclass(frozen=True)
class PlantSnapshot:
    """The exact state of a :class:`DartHexapod` at time ``t`` (:meth:`DartHexapod.snapshot`): generalized
    positions and velocities (free joint of the body first: rotation vector, translation; then the 18
    joints), the servo targets and the last step's contact readings."""

    t: float
    positions: np.ndarray
    velocities: np.ndarray
    q_target: np.ndarray
    q_target_prev: np.ndarray
    target_changed: bool
    ff_active: bool
    forces: np.ndarray
    force_world: np.ndarray
    body_contact: bool
    link_contact: np.ndarray
    n_steps: int

    def replace(self, **changes) -> PlantSnapshot:
        return dataclasses.replace(self, **changes)

    def interpolate(self, other: PlantSnapshot, tau: float) -> PlantSnapshot:
        """``other`` with positions and velocities moved back to ``self + tau (other - self)`` in time: the 18
        joint angles by cubic Hermite from their velocities, the body's free joint and every velocity linearly
        (everything else, the contact readings of the last step included, is ``other``'s)."""
        d = other.t - self.t
        pos = self.positions + tau * (other.positions - self.positions)
        h00, h10, h01, h11 = (2 * tau**3 - 3 * tau**2 + 1, tau**3 - 2 * tau**2 + tau, -2 * tau**3 + 3 * tau**2,
                              tau**3 - tau**2)
        pos[6:] = (h00 * self.positions[6:] + h10 * d * self.velocities[6:] + h01 * other.positions[6:]
                   + h11 * d * other.velocities[6:])
        vel = self.velocities + tau * (other.velocities - self.velocities)
        return dataclasses.replace(other, positions=pos, velocities=vel)


def check_explicit_ankle(ankle: AnkleSpring, foot_mass: float, h: float) -> None:
    """Refuse an ankle the DART plant's explicit spring-damper cannot step stably at ``h``: the free foot
    (mass ``foot_mass`` on its slide) under ``x'' = -(k x + c x') / m`` integrated as DART does (velocity first,
    then position, the force from the step's start) grows unless the step's amplification matrix has spectral
    radius below 1."""
    k, c, m = ankle.stiffness, ankle.damping, foot_mass
    a = np.array([[1.0 - h * h * k / m, h * (1.0 - h * c / m)], [-h * k / m, 1.0 - h * c / m]])
    radius = float(max(abs(np.linalg.eigvals(a))))
    if not radius < 1.0:
        raise ParameterError(f"ankle stiffness {k:g} N/m, damping {c:g} N*s/m on a {m:g} kg foot is unstable in "
                             f"DART's {h * 1e3:g} ms step (explicit spring-damper, amplification {radius:.3f}): use "
                             f"a softer or less damped ankle, a smaller robot.time_step, or robot.engine = mujoco")
