"""The hexapod in MuJoCo as a co-simulation block: the same ports, names and units as the DART plant.

:class:`MujocoHexapod` is a :class:`~cpgsim.robots.plant_base.HexapodPlant` like
:class:`cpgsim.robots.dart.plant.DartHexapod` (same constructor arguments except ``detector``, same
parameters, same ports from the same compiled readout, :mod:`cpgsim.robots.readout` with ``root="quat"``),
so the controllers, outcomes, report and benchmark need no engine-specific code. The model is the MJCF of
:func:`cpgsim.robots.mujoco.mjcf.mjcf`, written from the same robot description
(:mod:`cpgsim.robots.description`) and terrain as the DART one.

Servos: DART's law, ``tau = -kp (q + h qd - q_target) - kd qd`` (``h`` the world step; DART integrates its
joint spring implicitly, which is where ``h qd`` comes from). Here each joint's ``general`` actuator has
``gain = kp``, ``bias = (0, -kp, -(kd + h kp))`` and ``ctrl = q_target``: the same force, its velocity
part integrated implicitly by MuJoCo's ``implicitfast`` integrator. ``velocity_ff`` adds
``kd/kp * dq_target/dt`` to ``ctrl`` (DART adds ``kd dq_target/dt`` to the joint force: the same).

Contacts: after each MuJoCo step, each active contact between a robot geom and the terrain is read with
``mj_contactForce`` (contact frame: normal, two tangents; the frame's normal points from ``geom1`` to
``geom2`` and the force is the one ``geom1`` exerts on ``geom2``); rotated into the world frame and signed as
the force ON the robot, it is summed per leg (foot sphere, and the tibia box with ``sense_shank``). Body
box contacts set ``body_contact``; coxa/femur contacts are :meth:`link_contacts`. Over a macro step of
several MuJoCo steps the force is averaged, as in the DART plant.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import mujoco
import numpy as np

from cpgsim.components.core import ModelError, ParameterError
from cpgsim.components.geometry import LEG_NAMES, YU_SIM, RobotGeometry
from cpgsim.harness.cosim.contracts import FusedLoopBlock, FusedRequest, ResumableBlock
from cpgsim.harness.native import NativeUnavailable
from cpgsim.robots.description import CONTACT_OTHER, JOINT_NAMES, AnkleSpring, describe_hexapod, foot_positions_body
from cpgsim.robots.disturbance import Push
from cpgsim.robots.mujoco.mjcf import ContactModel, mjcf
from cpgsim.robots.plant_base import HexapodPlant
from cpgsim.robots.readout import StateLayout
from cpgsim.robots.terrain import Terrain


class MujocoHexapod(HexapodPlant, ResumableBlock, FusedLoopBlock):
    """The hexapod on a terrain in MuJoCo, stepped by the co-simulation master (ports: the DART plant's).

    Constructor: the arguments of :class:`~cpgsim.robots.plant_base.HexapodPlant` (amputated legs' geoms get
    ``contype = conaffinity = 0``; pushes are applied through ``xfrc_applied`` at every MuJoCo step they
    cover, by the C step, or by the Python sub-steps without one; the fused loop takes no pushes); ``native``: use
    the C macro step when it can be built (default); ``contact`` a :class:`~cpgsim.robots.mujoco.mjcf.ContactModel`
    (its ``timestep`` is the MuJoCo step; ``do_step``'s ``dt`` must be a multiple of it). ``time_step``,
    if given, replaces ``contact.timestep``.
    """

    engine = "mujoco"
    READOUT_ROOT = "quat"

    def __init__(self, name: str = "robot", geometry: RobotGeometry = YU_SIM, terrain: Terrain | None = None,
                 q0: Sequence[float] | None = None, body_height: float | None = None,
                 contact: ContactModel | None = None, time_step: float | None = None, sense_shank: bool = True,
                 settle: float = 0.0, native: bool = True, disturbances: Sequence[Push | Mapping] | None = None,
                 amputated: Sequence[int] = (), ankle: AnkleSpring | Mapping | None = None, **params: float) -> None:
        contact = contact or ContactModel()
        if time_step is not None:
            if not (math.isfinite(time_step) and time_step > 0):
                raise ParameterError(f"time_step must be > 0, got {time_step!r}")
            contact = ContactModel(**{**contact.__dict__, "timestep": float(time_step)})
        self.contact = contact
        self.time_step = contact.timestep
        self.native = bool(native)
        self.native_step = None
        self.model: mujoco.MjModel | None = None
        self.data: mujoco.MjData | None = None
        super().__init__(name, geometry, terrain, q0, body_height, sense_shank, settle, disturbances, amputated,
                         ankle=ankle, **params)

    @property
    def is_set_up(self) -> bool:
        return self.data is not None

    def set(self, **values: float) -> MujocoHexapod:
        """Set parameters; on a set-up plant, gains apply from the next step (friction needs a new setup)."""
        super().set(**values)
        if self.model is not None:
            self._apply_gains()
        return self

    def _apply_gains(self) -> None:
        v = self.values
        kp, kd, h = v["kp"], v["kd"], self.time_step
        self.model.actuator_gainprm[:, 0] = kp
        self.model.actuator_biasprm[:, 0] = 0.0
        self.model.actuator_biasprm[:, 1] = -kp
        self.model.actuator_biasprm[:, 2] = -(kd + h * kp)
        self._target_changed = True

    # -- lifecycle --------------------------------------------------------------------------------
    def xml(self) -> str:
        """The MJCF of this plant (robot at the world origin, joints at 0)."""
        return mjcf(self.geometry, self.terrain, friction=self.values["friction"], contact=self.contact,
                    ankle=self.ankle)

    def setup(self, t0: float) -> None:
        """Build the model, place the robot (lowest foot touching the ground), set the servos; clock at ``t0``."""
        self.terminate()
        model = mujoco.MjModel.from_xml_string(self.xml())
        shapes = describe_hexapod(self.geometry, ankle=self.ankle).shapes()
        for i in self.amputated:  # an amputated leg keeps its links and mass but touches nothing
            for spec in shapes:
                if spec.leg != i:
                    continue
                gid = model.geom(spec.name).id
                model.geom_contype[gid] = 0
                model.geom_conaffinity[gid] = 0
        data = mujoco.MjData(model)
        self.model, self.data = model, data
        data.qpos[:] = self.initial_qpos()
        data.qvel[:] = 0.0
        mujoco.mj_forward(model, data)
        self._apply_gains()

        self._geom_code = np.full(model.ngeom, CONTACT_OTHER, dtype=np.int64)
        for spec in shapes:
            self._geom_code[model.geom(spec.name).id] = spec.contact_code(self.sense_shank)
        self._geom_codes = self._geom_code.tolist()  # Python ints: the per-contact lookups of _robot_contacts
        self._reset_readings()
        self._cf = np.zeros(6)
        self._bind_readout()
        self.native_step = None
        self._body_id = model.body("body").id
        if self.native:
            try:
                from cpgsim.robots.mujoco.native import NativeMujocoStep

                self.native_step = NativeMujocoStep(model, data, self._geom_code, force=self._force_world,
                                                    pushes=self.pushes, body=self._body_id)
            except NativeUnavailable:  # no compiler or no libmujoco: Python sub-steps (slower, same results)
                self.native_step = None
        resume = self._take_resume(t0)
        if resume is not None:
            self.restore(resume)
            return
        self._settle(self.settle)
        data.time = float(t0)
        self._t = float(t0)
        self.update_outputs()

    def initial_qpos(self) -> np.ndarray:
        """Where :meth:`setup` places the robot (MuJoCo's ``qpos``, 25 values): the body at the world origin's
        ``x, y``, at ``body_height`` (default: the lowest foot touching the ground), level, facing ``+y``
        (quaternion ``1, 0, 0, 0``), the joints at ``q0`` (a compliant ankle's slide after each leg's three, at
        its rest length 0: 31 values)."""
        z = self.body_height if self.body_height is not None else self._touching_height(
            foot_positions_body(self.geometry, self.q0))
        joints = self.q0 if self.ankle is None else np.hstack([self.q0.reshape(6, 3), np.zeros((6, 1))]).ravel()
        return np.concatenate(([0.0, 0.0, z, 1.0, 0.0, 0.0, 0.0], joints))

    def state_layout(self) -> StateLayout:
        """MuJoCo's ``qpos``/``qvel`` as the compiled model numbers them (joint addresses by name)."""
        if self.ankle is None:
            return StateLayout.rigid(self.READOUT_ROOT)
        m = self.model
        names = [f"{leg}_{j}" for leg in LEG_NAMES for j in JOINT_NAMES]
        return StateLayout(int(m.nq), int(m.nv), tuple(int(m.joint(n).qposadr[0]) for n in names),
                           tuple(int(m.joint(n).dofadr[0]) for n in names),
                           tuple(int(m.joint(f"{leg}_ankle").qposadr[0]) for leg in LEG_NAMES))

    def terminate(self) -> None:
        """Keep the final state (:attr:`last_snapshot`), then drop the model."""
        if self.data is not None:
            self.last_snapshot = self.snapshot()
        self.native_step = None
        self.model = None
        self.data = None

    # -- exact state ------------------------------------------------------------------------------
    def snapshot(self) -> MujocoSnapshot:
        """Everything the next steps depend on: MuJoCo's integration state (``mj_getState`` with
        ``mjSTATE_INTEGRATION``: time, ``qpos``, ``qvel``, actuator activations, the solver's warm start,
        controls, applied forces), the servo targets and the last step's contact readings."""
        if self.data is None:
            raise ModelError(f"{self.name}: snapshot before setup")
        spec = mujoco.mjtState.mjSTATE_INTEGRATION
        state = np.zeros(mujoco.mj_stateSize(self.model, spec))
        mujoco.mj_getState(self.model, self.data, state, spec)
        return MujocoSnapshot(
            t=self._t, state=state, q_target=self._q_target.copy(),
            q_target_prev=np.array(self._q_target_prev, dtype=float), target_changed=self._target_changed,
            ff_active=self._ff_active, force_world=self._force_world.copy(), body_contact=self._body_contact,
            link_contact=self._link_contact.copy(), n_steps=self._n_steps)

    def restore(self, snap: MujocoSnapshot) -> None:
        """Put a set-up plant into the state ``snap`` (see :meth:`snapshot`)."""
        if self.data is None:
            raise ModelError(f"{self.name}: restore before setup")
        if not isinstance(snap, MujocoSnapshot):
            raise ModelError(f"{self.name}: a {type(snap).__name__} is not a MuJoCo plant's state")
        spec = mujoco.mjtState.mjSTATE_INTEGRATION
        if snap.state.shape != (mujoco.mj_stateSize(self.model, spec),):
            raise ModelError(f"{self.name}: a snapshot of {snap.state.size} values does not fit this model")
        mujoco.mj_setState(self.model, self.data, snap.state, spec)
        mujoco.mj_forward(self.model, self.data)
        self._t = float(snap.t)
        self._q_target = snap.q_target.copy()
        self._q_target_prev = snap.q_target_prev.copy()
        self._target_changed = snap.target_changed
        self._ff_active = snap.ff_active
        self._force_world[:] = snap.force_world
        self._body_contact = snap.body_contact
        self._link_contact[:] = snap.link_contact
        self._n_steps = snap.n_steps
        self.update_outputs()

    # -- stepping (the macro step, averaging and servo law: HexapodPlant) ------------------------------
    def _apply_servo(self, q_target: np.ndarray, velocity: np.ndarray | None) -> None:
        """``ctrl = q_target`` (+ ``kd/kp * dq_target/dt`` with ``velocity_ff``): the actuators' gain and bias
        (:meth:`_apply_gains`) make that the servo law."""
        ctrl = q_target.copy()
        if velocity is not None:
            v = self.values
            ctrl += v["kd"] / v["kp"] * velocity
        self.data.ctrl[:] = ctrl

    def _settle(self, seconds: float) -> None:
        """:meth:`HexapodPlant._settle` with the C step: once the servo law has nothing left to apply (its
        :meth:`_update_servo` is then a no-op), the remaining settle steps in one C call, each step as
        ``_native_steps(1)`` does it (the same ``mj_step``s and contact sums, the last step's readings), the
        outputs read once at the end instead of after every step (they depend on the state only)."""
        if self.native_step is None:
            super()._settle(seconds)
            return
        steps, k = int(round(seconds / self.time_step)), 0
        while k < steps and (self._target_changed or self._ff_active):
            self._update_servo(self.time_step)
            self._native_steps(1)
            k += 1
        if k < steps:
            self.native_step.settle(steps - k)
            self._take_c_readings()
            self.update_outputs()

    def _native_steps(self, n: int, t: float | None = None) -> bool:
        """``n`` MuJoCo steps in C from ``t`` (the contact sums averaged there, the pushes applied there), then the
        outputs."""
        self.native_step.run(n, t)
        self._take_c_readings()
        self.update_outputs()
        return True

    def _world_step(self, pushes: Sequence[Push]) -> None:
        """One ``mj_step``; the pushes as the body's ``xfrc_applied`` for that step (:meth:`_push_wrench`)."""
        if not pushes:
            mujoco.mj_step(self.model, self.data)
            return
        data, b = self.data, self._body_id
        data.xfrc_applied[b] = self._push_wrench(pushes)
        mujoco.mj_step(self.model, data)
        data.xfrc_applied[b] = 0.0

    def _push_wrench(self, pushes: Sequence[Push]) -> list[float]:
        """The forces summed and the torque of each about the body's centre of mass, ``(xpos + R point - xipos) x
        force``: the C step's ``cpgsim_push_wrench`` (robots/mujoco/c/mujoco_step.h), the same sums in the same
        order, so the Python and the C step give the same numbers."""
        data, b = self.data, self._body_id
        x, R, c = data.xpos[b].tolist(), data.xmat[b].tolist(), data.xipos[b].tolist()
        w = [0.0] * 6
        for push in pushes:
            f0, f1, f2 = push.force_N
            q0, q1, q2 = push.point_m
            r0, r1, r2 = ((x[j] + (R[3 * j] * q0 + R[3 * j + 1] * q1 + R[3 * j + 2] * q2)) - c[j] for j in range(3))
            w[0] += f0
            w[1] += f1
            w[2] += f2
            w[3] += r1 * f2 - r2 * f1
            w[4] += r2 * f0 - r0 * f2
            w[5] += r0 * f1 - r1 * f0
        return w

    # -- the closed loop in C (cpgsim.harness.cosim.fused) ----------------------------------------------------
    def fused_loop(self, request: FusedRequest):
        """A :class:`~cpgsim.robots.mujoco.native.FusedLoop` running this plant with the controller's bound
        compiled step in one C loop (the master's fast path, :mod:`cpgsim.harness.cosim.fused`), or None when this
        set-up cannot (no native step or compiled readout, ``velocity_ff`` on, pushes, an input that is not
        ``q_target``)."""
        if self.native_step is None or self._fused_refusal(request):
            return None
        indices = request.indices(self.output_slices, "q_target", 18)
        if indices is None:
            return None
        from cpgsim.robots.mujoco.native import FusedLoop

        return FusedLoop(self, self.native_step, request, *indices)

    def _take_c_readings(self) -> None:
        """The C step's or loop's contact sums and flags (body, then the six legs' links) into the buffers."""
        flags = self.native_step.flags
        self._force_world[:] = self.native_step.force
        self._body_contact = bool(flags[0])
        self._link_contact[:] = flags[1:] > 0.5

    def _robot_contacts(self):
        """The active contacts with a robot geom: the contact frame's normal points from ``geom1`` to ``geom2``
        and ``mj_contactForce`` gives the force ``geom1`` exerts on ``geom2``, so a robot ``geom2`` has sign +1."""
        codes = self._geom_codes
        data = self.data
        for k in range(data.ncon):
            c = data.contact[k]
            code = codes[c.geom2]
            if code != CONTACT_OTHER:
                yield code, 1.0, (k, c)
                continue
            code = codes[c.geom1]
            if code != CONTACT_OTHER:
                yield code, -1.0, (k, c)

    def _contact_force(self, contact) -> list[float]:
        """``mj_contactForce`` (contact frame: normal, two tangents) rotated into the world frame."""
        k, c = contact
        cf = self._cf
        mujoco.mj_contactForce(self.model, self.data, k, cf)
        return (c.frame.reshape(3, 3).T @ cf[:3]).tolist()

    def _read_state(self) -> None:
        self._pos[:] = self.data.qpos
        self._vel[:] = self.data.qvel

    # -- helpers (time, toe_force_world, link_contacts, body_contact, set_inputs, fell: HexapodPlant) ------

    def total_mass(self) -> float:
        """Mass of the robot in the compiled model (kg)."""
        return float(self.model.body_mass[1:].sum())

    def _state_finite(self) -> bool:
        return bool(np.all(np.isfinite(self.data.qpos)))

    def _body_rotation(self) -> np.ndarray:
        return self.data.xmat[self._body_id].reshape(3, 3)


@dataclass(frozen=True)
class MujocoSnapshot:
    """The exact state of a :class:`MujocoHexapod` at time ``t`` (:meth:`MujocoHexapod.snapshot`)."""

    t: float
    state: np.ndarray
    q_target: np.ndarray
    q_target_prev: np.ndarray
    target_changed: bool
    ff_active: bool
    force_world: np.ndarray
    body_contact: bool
    link_contact: np.ndarray
    n_steps: int
