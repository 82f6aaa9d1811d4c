"""The DART hexapod as a co-simulation block (the plant of the 1 kHz control loop).

Ports (units SI; joint vectors leg-major: leg 0 ``alpha, beta, gamma``, leg 1 ..., leg 5):

============== ===== ===== =========================================================================
port           dir   shape meaning
============== ===== ===== =========================================================================
q_target       in    18    joint position targets of the servos (rad)
q              out   18    joint angles (rad)
qd             out   18    joint velocities (rad/s)
toe_force      out   18    per leg ``(Fx lateral, Fy forward, Fz vertical)`` in the BODY frame: the
                           force the ground exerts on the foot (``Fz > 0`` when standing), N
body_position  out   3     body frame origin (centre of the body box) in the world, m
body_rpy       out   3     ``(roll, pitch, yaw)`` with ``R = Rz(yaw) Rx(pitch) Ry(roll)``, rad
foot_position  out   18    foot sphere centres in the world frame, m
body_contact   out   1     1 when the body box touched anything during the last step (boolean)
============== ===== ===== =========================================================================

Roll turns about the forward axis ``y`` (positive: right side down), pitch about the lateral axis
``x`` (positive: nose up), yaw about ``z`` (positive: turning left). No output reads an input in
the same step (no direct feedthrough).

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
(:mod:`cpgsim.robots.dart_native`: ``setForces``, ``World::step``, the contact sums, the state read and
the readout, through the DART symbols dartpy exports), and with a compiled controller and no other
co-simulation block the whole loop runs in C, chunks of 100 macro steps per call
(:meth:`DartHexapod.closed_loop`, :mod:`cpgsim.robots.dart_fused`). The Python loop below stays the
reference and the fallback (``CPGSIM_DART_NATIVE=0``, pushes, several world steps per macro step; the C
step is checked against it over each set-up's first steps): one ``setForces`` for the servos; collision
objects identified by their (kept-alive) wrappers' ``id()`` after the first sight (the terrain is usually
object 1, so object 2 is looked at first); every output (foot centres, body-frame toe forces,
roll/pitch/yaw) from one compiled CasADi function (:mod:`cpgsim.robots.readout`) on the skeleton's
positions and velocities.
"""

from __future__ import annotations

import dataclasses
import math
import struct
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import dartpy as dart
import numpy as np

from cpgsim.components.core import CoSimBlock, ModelError, ParameterError
from cpgsim.components.geometry import YU_SIM, RobotGeometry, leg_ik
from cpgsim.harness.native import NativeFunction, NativeUnavailable
from cpgsim.robots import dart_native
from cpgsim.robots.disturbance import Push, active_pushes, as_pushes
from cpgsim.robots.hexapod import HexapodModel, build_hexapod, tilt_angle
from cpgsim.robots.readout import OUTPUT_PORTS, readout_function
from cpgsim.robots.terrain import Terrain, flat

GRAVITY = 9.81
_free_to_transform = dart.dynamics.FreeJoint.convertToTransform
DETECTORS = {
    "dart": dart.collision.DARTCollisionDetector,
    "fcl": dart.collision.FCLCollisionDetector,
    "bullet": dart.collision.BulletCollisionDetector,
    "ode": dart.collision.OdeCollisionDetector,
}


def default_gains(geometry: RobotGeometry) -> tuple[float, float]:
    """Servo gains ``(kp, kd)`` scaled to the robot.

    ``kp = 10 m g (L_thigh + L_shank)``: the torque that holds a sixth of the weight at a lever
    of the leg length gives about 1/60 rad of deflection (YU_SIM: 96 N m/rad; prototype about
    3.1e4 N m/rad). ``kd = 2 sqrt(kp I)`` with ``I`` the leg's inertia about the beta axis at
    ``beta = 0, gamma = pi/2``: critical damping of a swinging leg (YU_SIM: about 1.1 N m s/rad).
    """
    leg = geometry.leg
    kp = 10.0 * geometry.mass * GRAVITY * (leg.thigh + leg.shank)
    inertia = (leg.thigh_mass * (leg.thigh / 2) ** 2 + leg.shank_mass * (leg.thigh**2 + (leg.shank / 2) ** 2)
               + leg.foot_mass * (leg.thigh**2 + leg.shank**2))
    kd = 2.0 * math.sqrt(kp * max(inertia, 1e-9))
    return float(f"{kp:.3g}"), float(f"{kd:.3g}")


def standing_posture(geometry: RobotGeometry) -> np.ndarray:
    """The 18 joint angles with every foot at the stance midpoint (``alpha = 0``), leg-major."""
    r, h = geometry.nominal_points()["stance_mid"]
    alpha, beta, gamma = leg_ik(geometry.leg, r, 0.0, h)
    return np.tile([alpha, beta, gamma], 6)


def rpy_from_rotation(R: np.ndarray) -> np.ndarray:
    """``(roll, pitch, yaw)`` of ``R = Rz(yaw) Rx(pitch) Ry(roll)`` (see the module docstring)."""
    pitch = math.asin(max(-1.0, min(1.0, float(R[2, 1]))))
    roll = math.atan2(-R[2, 0], R[2, 2])
    yaw = math.atan2(-R[0, 1], R[1, 1])
    return np.array([roll, pitch, yaw])


def rotation_from_rpy(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """Inverse of :func:`rpy_from_rotation`."""
    cr, sr, cp, sp, cy, sy = (math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch),
                              math.cos(yaw), math.sin(yaw))
    Rz = np.array([[cy, -sy, 0.0], [sy, cy, 0.0], [0.0, 0.0, 1.0]])
    Rx = np.array([[1.0, 0.0, 0.0], [0.0, cp, -sp], [0.0, sp, cp]])
    Ry = np.array([[cr, 0.0, sr], [0.0, 1.0, 0.0], [-sr, 0.0, cr]])
    return Rz @ Rx @ Ry


def declare_plant(block: CoSimBlock) -> None:
    """The hexapod plant's parameters and ports, the same in every engine (DART here, MuJoCo in
    :mod:`cpgsim.robots.mujoco_plant`): servo gains, friction, the joint targets in, and joint angles and
    velocities, toe forces, body pose, feet and body contact out."""
    kp, kd = default_gains(block.geometry)
    block.add_parameter("kp", kp, "N*m/rad", (0.0, math.inf), "joint servo stiffness", strict=True)
    block.add_parameter("kd", kd, "N*m*s/rad", (0.0, math.inf), "joint servo damping", strict=True)
    block.add_parameter("friction", 1.0, "1", (0.0, math.inf), "Coulomb friction of the robot's shapes",
                        strict=True)
    block.add_parameter("velocity_ff", 0.0, "1", (0.0, 1.0), "advance the servo rest position by "
                        "kd/kp * target velocity", kind="boolean")
    block.add_input("q_target", 18, "rad",
                    description="joint position targets, leg-major (alpha, beta, gamma)")
    block.add_output("q", 18, "rad", description="joint angles, leg-major")
    block.add_output("qd", 18, "rad/s", description="joint velocities, leg-major")
    block.add_output("toe_force", 18, "N", description="ground force on each foot "
                     "(Fx lateral, Fy forward, Fz vertical) in the body frame")
    block.add_output("body_position", 3, "m", description="body origin in the world frame")
    block.add_output("body_rpy", 3, "rad", description="roll (about y), pitch (about x), yaw (about z)")
    block.add_output("foot_position", 18, "m", description="foot centres in the world frame, leg-major")
    block.add_output("body_contact", 1, "1", kind="boolean",
                     description="1 when the body box touched anything during the last step")


class PlantCommon:
    """What hexapod plants of every engine share: taking the joint targets (``set_inputs``), the world
    steps per macro step, and the readings they keep between steps (``_t``, ``_force_world``,
    ``_link_contact``, ``_body_contact``, set by each engine's ``do_step``)."""

    name: str
    time_step: float
    _q_target: np.ndarray
    _target_changed: bool
    _steps_per: dict[float, int]
    _t: float
    _force_world: np.ndarray
    _link_contact: np.ndarray
    _body_contact: bool

    def _describe(self, geometry: RobotGeometry, terrain: Terrain | None, q0: Sequence[float] | None,
                  body_height: float | None, sense_shank: bool, settle: float,
                  disturbances: Sequence[Push | Mapping] | None = None) -> np.ndarray:
        """Check and keep the constructor arguments every engine takes; returns the start posture ``q0``."""
        self.set_disturbances(disturbances)
        if not isinstance(geometry, RobotGeometry):
            raise ParameterError(f"geometry must be a RobotGeometry, got {type(geometry).__name__}")
        if not (math.isfinite(settle) and settle >= 0):
            raise ParameterError(f"settle must be >= 0, got {settle!r}")
        self.geometry = geometry
        self.terrain = terrain if terrain is not None else flat()
        q0_arr = standing_posture(geometry) if q0 is None else np.asarray(q0, dtype=float).ravel()
        if q0_arr.shape != (18,) or not np.all(np.isfinite(q0_arr)):
            raise ParameterError(f"q0 needs 18 finite joint angles, got shape {q0_arr.shape}")
        self.q0 = q0_arr
        self.body_height = body_height
        self.sense_shank = bool(sense_shank)
        self.settle = float(settle)
        return q0_arr

    def set_inputs(self, values: Mapping[str, np.ndarray]) -> None:
        q = values.get("q_target")
        if q is None:
            return
        q = np.asarray(q, dtype=float)
        if q.shape != (18,):
            q = q.ravel()
            if q.shape != (18,):
                raise ModelError(f"{self.name}.q_target needs 18 values, got {q.size}")
        if not math.isfinite(float(q.sum())):  # a sum is finite only if every element is
            raise ModelError(f"{self.name}.q_target is not finite: {q}")
        if q.tobytes() != self._q_target.tobytes():  # cheaper than array_equal on 18 values
            self._q_target = q.copy()
            self._target_changed = True

    def _steps_for(self, dt: float) -> int:
        n = self._steps_per.get(dt)
        if n is None:
            h = self.time_step
            n = int(round(dt / h))
            if n < 1 or abs(n * h - dt) > 1e-9 * max(1.0, dt):
                raise ModelError(f"{self.name}: dt = {dt} is not a positive multiple of the world step {h}")
            self._steps_per[dt] = n
        return n

    @property
    def time(self) -> float:
        return self._t

    def set_disturbances(self, disturbances: Sequence[Push | Mapping] | None) -> None:
        """Replace the pushes (as the constructor's ``disturbances``); from the next :meth:`setup` on."""
        self.pushes = as_pushes(disturbances, f"{self.name}: disturbances")

    def pushes_at(self, t: float) -> list[Push]:
        """The pushes (:mod:`cpgsim.robots.disturbance`) a world step starting at ``t`` feels."""
        return active_pushes(self.pushes, t, self.time_step) if self.pushes else []

    def toe_force_world(self) -> np.ndarray:
        """Per-leg ground force on the foot in the world frame of the last step, shape (6, 3)."""
        return self._force_world.reshape(6, 3).copy()

    def link_contacts(self) -> np.ndarray:
        """Per leg, whether a coxa or femur (or an unsensed tibia) touched something in the last step."""
        return self._link_contact.copy()

    def body_contact(self) -> bool:
        """Whether the body box touched anything in the last step."""
        return bool(self._body_contact)


class DartHexapod(PlantCommon, CoSimBlock):
    """The hexapod on a terrain in a DART world, stepped by the co-simulation master.

    Constructor arguments (fixed for the block's life; parameters go in ``**params``):

    - ``geometry``: a :class:`~cpgsim.components.geometry.RobotGeometry` (default ``YU_SIM``);
    - ``terrain``: a :class:`~cpgsim.robots.terrain.Terrain` (default flat ground);
    - ``q0``: initial joint angles (18, rad; default :func:`standing_posture`);
    - ``body_height``: initial height of the body frame (m); default: the lowest foot sphere just
      touches the ground under it (body level, at the world origin, facing ``+y``);
    - ``detector``: ``'dart'`` (default: exact for spheres and boxes, the fastest measured),
      ``'fcl'``, ``'bullet'`` or ``'ode'``;
    - ``time_step``: the DART world step (s, default 1 ms); ``do_step``'s ``dt`` must be a
      multiple of it;
    - ``sense_shank``: count tibia contacts as toe forces (default ``True``);
    - ``settle``: seconds simulated in :meth:`setup` with the targets held at ``q0`` before the
      clock is set to ``t0`` (so ``t0``'s outputs show a loaded, resting robot); default 0;
    - ``disturbances``: pushes on the body (:class:`~cpgsim.robots.disturbance.Push` or mappings with
      ``start_s``, ``duration_s``, ``force_N`` in the world frame, ``point_m`` in the body frame),
      applied at every world step they cover.

    Parameters: ``kp`` (N m/rad, > 0), ``kd`` (N m s/rad, > 0), ``friction`` (Coulomb coefficient
    of the robot's shapes, > 0; the ground has its terrain's), ``velocity_ff`` (0/1).
    """

    def __init__(self, name: str = "robot", geometry: RobotGeometry = YU_SIM, terrain: Terrain | None = None,
                 q0: Sequence[float] | None = None, body_height: float | None = None, detector: str = "dart",
                 time_step: float = 1e-3, sense_shank: bool = True, settle: float = 0.0,
                 disturbances: Sequence[Push | Mapping] | None = None, **params: float) -> None:
        if detector not in DETECTORS:
            raise ParameterError(f"unknown collision detector {detector!r} (known: {', '.join(DETECTORS)})")
        if not (math.isfinite(time_step) and time_step > 0):
            raise ParameterError(f"time_step must be > 0, got {time_step!r}")
        self.name = name
        q0_arr = self._describe(geometry, terrain, q0, body_height, sense_shank, settle, disturbances)
        self.detector = detector
        self.time_step = float(time_step)
        self.world: dart.simulation.World | None = None
        self.model: HexapodModel | None = None
        self._q_target = q0_arr.copy()
        self._resume: PlantSnapshot | None = None
        self._native: dart_native.NativeDartStep | None = None
        self.last_snapshot: PlantSnapshot | None = None
        super().__init__(name, **params)

    # -- declaration ------------------------------------------------------------------------------
    def declare(self) -> None:
        declare_plant(self)

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
        self._terrain_skel = self.terrain.add_to(world)

        model = build_hexapod(self.geometry, friction=v["friction"])
        model.set_joint_angles(self.q0)
        model.set_body_pose([0.0, 0.0, 0.0])
        z = self.body_height if self.body_height is not None else self._touching_height(model)
        model.set_body_pose([0.0, 0.0, z])
        for j in model.joints:  # rest at 0: the target enters as the force kp * q_target (see do_step)
            j.setSpringStiffness(0, v["kp"])
            j.setDampingCoefficient(0, v["kd"])
            j.setRestPosition(0, 0.0)
        world.addSkeleton(model.skeleton)
        self.world, self.model = world, model

        # collision shape -> leg index (toe), _LINK + leg (other leg links) or _BODY. Shapes are
        # identified by object identity: pybind11 hands back the registered wrapper of a shape we
        # keep alive, so id() of collisionObject.getShape() is a cheap, stable key.
        self._shapes = []  # keep the wrappers alive so id() stays valid
        self._shape_leg: dict[int, int] = {}
        for i, foot in enumerate(model.feet):
            self._register(foot.getShape(), i)
        for i, bodies in enumerate(model.link_bodies):
            for k, bn in enumerate(bodies):
                for sn in bn.getShapeNodes():
                    if sn.getName().endswith("_foot"):
                        continue
                    self._register(sn.getShape(), i if (k == 2 and self.sense_shank) else _LINK + i)
        for sn in model.body.getShapeNodes():
            self._register(sn.getShape(), _BODY)

        # collision object wrapper -> code (filled on first sight; the wrappers are kept alive so their id()
        # stays valid): saves two getShape() calls per contact and step
        self._objects: list = []
        self._object_code: dict[int, int] = {}
        self._skel = model.skeleton
        self._steps_per: dict[float, int] = {}
        self._q_target = self.q0.copy()
        self._q_target_prev = self.q0.copy()
        self._target_changed = True
        self._ff_active = False
        self._forces = np.zeros(model.skeleton.getNumDofs())
        self._n_steps = 0
        self._force_list = [0.0] * 18
        self._body_contact = False
        self._link_contact = np.zeros(6, dtype=bool)
        self._bind_readout()
        self._bind_native()
        resume, self._resume = self._resume, None
        if resume is not None:
            if abs(resume.t - float(t0)) > 0.5 * self.time_step:
                raise ModelError(f"{self.name}: resuming a state saved at t = {resume.t} in a run from t0 = {t0}")
            self.restore(resume)
            return
        self._settle(self.settle)
        world.setTime(float(t0))
        self._t = float(t0)
        self._update_outputs()

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
        self._update_outputs()

    def resume_from(self, snap: PlantSnapshot | None) -> None:
        """Make the next :meth:`setup` start in ``snap`` (no settling) instead of the initial posture."""
        self._resume = snap

    def _bind_readout(self) -> None:
        """The compiled sensor readout (:mod:`cpgsim.robots.readout`) on this plant's buffers."""
        self._pos, self._vel = np.zeros(24), np.zeros(24)
        self._force_world = np.zeros(18)
        self._force_bytes = memoryview(self._force_world).cast("B")
        self._contact = np.zeros(1)
        self._readout_out = np.zeros(sum(n for _, n in OUTPUT_PORTS))
        fn = _readout_for(self.geometry)
        try:
            self._readout = NativeFunction(fn, [self._pos, self._vel, self._force_world, self._contact],
                                           [self._readout_out])
        except NativeUnavailable:  # no C compiler: CasADi's VM evaluates the same function (slower)
            def evaluate() -> None:
                self._readout_out[:] = np.asarray(fn(self._pos, self._vel, self._force_world, self._contact)).ravel()
            self._readout = evaluate

    def _bind_native(self) -> None:
        """The C step (:mod:`cpgsim.robots.dart_native`) on this plant's world and buffers, when it works."""
        self._native = None
        if not dart_native.enabled():
            return
        readout = self._readout.c_entry() if isinstance(self._readout, NativeFunction) else None
        try:
            self._native = dart_native.NativeDartStep(
                self.world, self._skel, self._forces, self._force_world, self._link_contact, self._pos, self._vel,
                self._contact, readout)
        except NativeUnavailable as exc:
            self._drop_native(exc, stacklevel=4)
        if self._native is not None and readout is None:
            step = self._native.step

            def step_and_readout() -> int:  # the readout in CasADi's VM (no C compiler for it)
                rc = step()
                if rc in (0, 2):
                    self._readout()
                return rc
            self._native.step = step_and_readout

    def _check_native(self) -> None:
        """Compare the C step's contact sums and state with the Python readout of the same step (bit for bit);
        on any difference keep Python from now on (the Python values are in place either way)."""
        native = self._native
        native.checks_left -= 1
        c_values = (self._force_world.tobytes(), self._link_contact.tobytes(), self._body_contact,
                    self._pos.tobytes(), self._vel.tobytes())
        self._read_contacts()
        self._update_outputs()
        if c_values != (self._force_world.tobytes(), self._link_contact.tobytes(), self._body_contact,
                        self._pos.tobytes(), self._vel.tobytes()):
            self._drop_native("the C step's contact readout differs from the bindings'", stacklevel=4)

    def _drop_native(self, reason: object, stacklevel: int) -> None:
        """Step DART in Python from now on (the C step is closed), saying why."""
        warnings.warn(f"{self.name}: DART's step stays in Python ({reason})", RuntimeWarning, stacklevel=stacklevel)
        if self._native is not None:
            self._native.close()
        self._native = None

    def _native_step(self) -> None:
        """One world step through the C step: ``setForces``, ``world.step()``, contact sums, outputs."""
        native = self._native
        rc = native.step()
        if rc == 1:  # a collision object met for the first time: this step's contacts in Python
            self._read_contacts()
            self._update_outputs()
        elif rc < 0:
            raise RuntimeError("compiled function of the plant readout reported an evaluation error")
        else:
            self._body_contact = rc == 2
            if native.checks_left:
                self._check_native()

    def _settle(self, seconds: float) -> None:
        """Simulate ``seconds`` with the targets held (before the clock starts; no pushes)."""
        for _ in range(int(round(seconds / self.time_step))):
            self._update_servo_forces(self.time_step)
            if self._native is not None:  # the same operations in C (its outputs are read again after)
                self._native_step()
                continue
            self._skel.setForces(self._forces)
            self.world.step()
            self._read_contacts()

    def _register(self, shape: dart.dynamics.Shape, code: int) -> None:
        self._shapes.append(shape)
        self._shape_leg[id(shape)] = code

    def _touching_height(self, model: HexapodModel) -> float:
        feet = model.foot_positions()  # body frame origin at the world origin, level
        ground = np.asarray(self.terrain.height_at(feet[:, 0], feet[:, 1]), dtype=float)
        ok = np.isfinite(ground)
        if not ok.any():
            raise ModelError("no foot of the initial posture is above ground")
        return float(np.max(ground[ok] + self.geometry.leg.foot_radius - feet[ok, 2]))

    def terminate(self) -> None:
        """Keep the final state (:attr:`last_snapshot`), then drop the world (contacts of a removed world must
        not be touched again: reading them segfaulted)."""
        if self.world is not None:
            try:
                self.last_snapshot = self.snapshot()
            except (AttributeError, ModelError):  # a setup that failed half-way: nothing to continue from
                self.last_snapshot = None
        if self._native is not None:
            self._native.close()  # holds the world's C++ address
        self._native = None
        self.world = None
        self.model = None
        self._shapes = []
        self._shape_leg = {}
        self._objects = []
        self._object_code = {}

    # -- stepping ---------------------------------------------------------------------------------
    def do_step(self, t: float, dt: float) -> None:
        """Advance ``[t, t + dt]``: ``dt / time_step`` world steps with the servo targets held."""
        if self.world is None:
            raise ModelError(f"{self.name}: do_step before setup")
        n = self._steps_for(dt)
        if abs(t - self._t) > 0.5 * self.time_step:
            raise ModelError(f"{self.name}: do_step at t = {t}, but the plant is at t = {self._t}")
        self._update_servo_forces(dt)
        world, skel, forces = self.world, self._skel, self._forces
        if self._native is not None and n == 1 and not self.pushes:
            self._native_step()
            self._t = t + dt
            self._n_steps += 1
            return
        if n == 1 and not self.pushes:
            skel.setForces(forces)
            world.step()
            self._read_contacts()
        else:
            body_node = self.model.body
            total = np.zeros(18)
            body = False
            link = np.zeros(6, dtype=bool)
            for i in range(n):
                skel.setForces(forces)  # world.step() clears them, and the external forces too
                for push in self.pushes_at(t + i * self.time_step):
                    body_node.addExtForce(np.asarray(push.force_N), np.asarray(push.point_m), False, True)
                world.step()
                self._read_contacts()
                total += self._force_world
                body |= self._body_contact
                link |= self._link_contact
            self._force_world[:] = total / n
            self._body_contact = body
            self._link_contact[:] = link  # in place: the C step holds this buffer
        self._t = t + dt
        self._n_steps += n
        self._update_outputs()

    def _update_servo_forces(self, dt: float) -> None:
        """Joint forces for the next world steps: ``kp q_target`` (+ ``kd dq_target/dt`` with ``velocity_ff``).

        DART's joint spring, at rest position 0, adds ``-kp (q + h qd) - kd qd`` implicitly, so the total
        is the servo law ``-kp (q + h qd - q_target) - kd qd`` of a spring whose rest position is the
        target -- one ``setForces`` call instead of 18 ``setRestPosition`` calls.
        """
        if self._target_changed or self._ff_active:
            v = self.values
            legs = self._forces[6:]
            np.multiply(self._q_target, v["kp"], out=legs)
            if v["velocity_ff"]:
                vel = (self._q_target - self._q_target_prev) / dt
                self._ff_active = bool(np.any(vel != 0.0))
                legs += v["kd"] * vel
            self._q_target_prev = self._q_target
            self._target_changed = False

    def _object_code_of(self, obj) -> int:
        """Code of a collision object (leg index, ``_LINK + leg``, ``_BODY`` or ``_OTHER``), registered on
        first sight (its wrapper is kept alive so ``id()`` identifies it from then on)."""
        code = self._shape_leg.get(id(obj.getShape()), _OTHER)
        self._objects.append(obj)
        self._object_code[id(obj)] = code
        if self._native is not None:
            try:
                self._native.register(obj, code)
            except NativeUnavailable as exc:
                self._drop_native(exc, stacklevel=3)
        return code

    def _read_contacts(self) -> None:
        """Sum the last collision result's contact forces per leg (world frame, force on the robot)."""
        f = self._force_list
        f[:] = _ZEROS18
        body = False
        link = self._link_contact
        link[:] = False
        lookup = self._object_code.get
        for c in self.world.getLastCollisionResult().getContacts():
            # c.force acts on object 1; the DART detector lists the terrain first, so look at object 2 first
            o2 = c.collisionObject2
            code = lookup(id(o2))
            if code is None:
                code = self._object_code_of(o2)
            sign = -1.0
            if code == _OTHER:
                o1 = c.collisionObject1
                code = lookup(id(o1))
                if code is None:
                    code = self._object_code_of(o1)
                if code == _OTHER:
                    continue
                sign = 1.0
            if code < _LINK:
                f0, f1, f2 = c.force.tolist()
                k = 3 * code
                f[k] += sign * f0
                f[k + 1] += sign * f1
                f[k + 2] += sign * f2
            elif code == _BODY:
                body = True
            else:
                link[code - _LINK] = True  # a coxa/femur (or unsensed shank) touched something
        _PACK18(self._force_bytes, 0, *f)  # 0.25 us; a numpy slice assignment from a list takes 0.8
        self._body_contact = body

    def _update_outputs(self) -> None:
        """The output ports from DART's state and the summed contacts (compiled readout, about 1 us)."""
        skel = self._skel
        self._pos[:] = skel.getPositions()
        self._vel[:] = skel.getVelocities()
        self._contact[0] = 1.0 if self._body_contact else 0.0
        self._readout()

    def get_outputs(self) -> dict[str, np.ndarray]:
        if self.world is None:
            raise ModelError(f"{self.name}: get_outputs before setup")
        out = self._readout_out.copy()  # the next do_step overwrites the bound buffer
        return {name: out[sl] for name, sl in _PORT_SLICES}

    # -- the closed loop in C --------------------------------------------------------------------
    def closed_loop(self, commit_fn: int, ctx: int, nx: int, nz: int, u: np.ndarray, y: np.ndarray,
                    u_map: list[tuple[slice, str]], inputs: dict[str, slice], yi: np.ndarray, dt: float):
        """A :class:`~cpgsim.robots.dart_fused.FusedLoop` running this plant with a controller's bound compiled
        step (``commit_fn(ctx, t, nx, nz)``, the ``cpgsim_step_commit`` of :mod:`cpgsim.harness.native`) in
        one C loop (the master's fast path, :mod:`cpgsim.harness.fused`), or None when this plant cannot: no C
        step or compiled readout, ``velocity_ff`` on, pushes, more than one world step per macro step, an
        input that is not ``q_target``.

        ``u_map``: which slice of the controller's input vector ``u`` takes which output port; ``inputs``: the
        slice of the controller's signals ``y`` feeding each input port; ``yi``: the recorded signals.
        """
        if (self._native is None or not isinstance(self._readout, NativeFunction) or self.values["velocity_ff"]
                or self.pushes or set(inputs) != {"q_target"} or self._steps_for(dt) != 1):
            return None
        from cpgsim.robots.dart_fused import FusedLoop

        sl = inputs["q_target"]
        qt_idx = np.arange(sl.start, sl.stop)
        if qt_idx.size != 18:
            return None
        ports = dict(_PORT_SLICES)
        u_idx: list[int] = []
        o_idx: list[int] = []
        for u_sl, port in u_map:
            o_sl = ports[port]
            u_idx += list(range(u_sl.start, u_sl.stop))
            o_idx += list(range(o_sl.start, o_sl.stop))
        self.output_slices = ports
        return FusedLoop(self, self._native, commit_fn, ctx, nx, nz, u, y, np.array(u_idx), np.array(o_idx), qt_idx,
                         np.asarray(yi))

    def _after_fused(self, t: float, q_target: np.ndarray, changed: bool, updated: bool) -> None:
        """The Python side brought up to date after the C loop stepped the plant to ``t`` (targets ``q_target``;
        ``updated``: some step took a new target, as :meth:`_update_servo_forces` does)."""
        self._n_steps += int(round((t - self._t) / self.time_step))
        self._t = t
        if updated:
            self._q_target = q_target.copy()
            self._q_target_prev = self._q_target
        self._target_changed = changed
        self._body_contact = bool(self._contact[0])

    # -- helpers ----------------------------------------------------------------------------------

    def fell(self, max_tilt: float = math.pi / 4) -> bool:
        """The robot has fallen: body touched the ground, tilt above ``max_tilt`` or non-finite state."""
        if self.world is None:
            return False
        if self._body_contact:
            return True
        pos = self.model.skeleton.getPositions()
        if not np.all(np.isfinite(pos)):
            return True
        return tilt_angle(_free_to_transform(pos[:6]).matrix()[:3, :3]) > max_tilt


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


def _readout_for(geometry: RobotGeometry):
    """The readout function of a geometry (built once per geometry and process)."""
    key = repr(geometry)
    fn = _READOUTS.get(key)
    if fn is None:
        fn = _READOUTS[key] = readout_function(geometry)
    return fn


_READOUTS: dict[str, object] = {}
_PORT_SLICES: list[tuple[str, slice]] = []
_k = 0
for _name, _size in OUTPUT_PORTS:
    _PORT_SLICES.append((_name, slice(_k, _k + _size)))
    _k += _size
_ZEROS18 = [0.0] * 18
_PACK18 = struct.Struct("18d").pack_into
_LINK = 10  # code of leg i's unsensed links: _LINK + i
_BODY = 100
_OTHER = 1000  # not the robot (terrain)
