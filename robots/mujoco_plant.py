"""The hexapod in MuJoCo as a co-simulation block: the same ports, names and units as the DART plant.

:class:`MujocoHexapod` is a drop-in for :class:`cpgsim.robots.plant.DartHexapod` (same constructor
arguments except ``detector``, same parameters ``kp``, ``kd``, ``friction``, ``velocity_ff``, same output
ports from the same compiled readout, :mod:`cpgsim.robots.readout` with ``root="quat"``), so the
controllers, outcomes, report and benchmark need no engine-specific code. The model is the MJCF of
:func:`cpgsim.robots.mjcf.mjcf`, generated from the same robot description and terrain as the DART one.

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

import mujoco
import numpy as np

from cpgsim.components.core import CoSimBlock, ModelError, ParameterError
from cpgsim.components.geometry import LEG_NAMES, YU_SIM, RobotGeometry
from cpgsim.harness.native import NativeFunction, NativeUnavailable
from cpgsim.robots.disturbance import Push
from cpgsim.robots.hexapod import foot_positions_body, tilt_angle
from cpgsim.robots.mjcf import ContactModel, mjcf
from cpgsim.robots.plant import PlantCommon, declare_plant
from cpgsim.robots.readout import OUTPUT_PORTS, readout_function
from cpgsim.robots.terrain import Terrain

_LINK = 10
_BODY = 100
_OTHER = 1000


class MujocoHexapod(PlantCommon, CoSimBlock):
    """The hexapod on a terrain in MuJoCo, stepped by the co-simulation master (ports: the DART plant's).

    Constructor: ``geometry``, ``terrain``, ``q0``, ``body_height``, ``sense_shank``, ``settle``,
    ``disturbances`` as :class:`~cpgsim.robots.plant.DartHexapod`; ``amputated``: leg indices whose links
    touch nothing (Fukuhara 2022, Sec. 3.2: they keep their mass); (pushes are applied through
    ``xfrc_applied`` at every MuJoCo step they cover, by the Python sub-steps: a run with pushes does not
    use the native step loop); ``contact`` a :class:`~cpgsim.robots.mjcf.ContactModel`
    (its ``timestep`` is the MuJoCo step; ``do_step``'s ``dt`` must be a multiple of it). ``time_step``,
    if given, replaces ``contact.timestep``.
    """

    engine = "mujoco"

    def __init__(self, name: str = "robot", geometry: RobotGeometry = YU_SIM, terrain: Terrain | None = None,
                 q0: Sequence[float] | None = None, body_height: float | None = None,
                 contact: ContactModel | None = None, time_step: float | None = None, sense_shank: bool = True,
                 settle: float = 0.0, native: bool = True, disturbances: Sequence[Push | Mapping] | None = None,
                 amputated: Sequence[int] = (), **params: float) -> None:
        self.name = name
        q0_arr = self._describe(geometry, terrain, q0, body_height, sense_shank, settle, disturbances)
        contact = contact or ContactModel()
        if time_step is not None:
            if not (math.isfinite(time_step) and time_step > 0):
                raise ParameterError(f"time_step must be > 0, got {time_step!r}")
            contact = ContactModel(**{**contact.__dict__, "timestep": float(time_step)})
        self.contact = contact
        self.time_step = contact.timestep
        self.native = bool(native)
        self.amputated = tuple(int(i) for i in amputated)
        if any(not 0 <= i < 6 for i in self.amputated):
            raise ParameterError(f"amputated legs must be leg indices 0-5, got {self.amputated}")
        self._native = None
        self.model: mujoco.MjModel | None = None
        self.data: mujoco.MjData | None = None
        self._q_target = q0_arr.copy()
        super().__init__(name, **params)

    # -- declaration (the DART plant's ports and parameters) ---------------------------------------
    def declare(self) -> None:
        declare_plant(self)

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
        return mjcf(self.geometry, self.terrain, friction=self.values["friction"], contact=self.contact)

    def setup(self, t0: float) -> None:
        """Build the model, place the robot (lowest foot touching the ground), set the servos; clock at ``t0``."""
        self.terminate()
        model = mujoco.MjModel.from_xml_string(self.xml())
        for i in self.amputated:  # an amputated leg keeps its links and mass but touches nothing
            for link in ("coxa_box", "femur_box", "tibia_box", "foot"):
                gid = model.geom(f"{LEG_NAMES[i]}_{link}").id
                model.geom_contype[gid] = 0
                model.geom_conaffinity[gid] = 0
        data = mujoco.MjData(model)
        self.model, self.data = model, data
        z = self.body_height if self.body_height is not None else self._touching_height()
        data.qpos[:3] = (0.0, 0.0, z)
        data.qpos[3:7] = (1.0, 0.0, 0.0, 0.0)
        data.qpos[7:] = self.q0
        data.qvel[:] = 0.0
        mujoco.mj_forward(model, data)
        self._apply_gains()

        self._geom_code = np.full(model.ngeom, _OTHER, dtype=np.int64)
        for i, leg in enumerate(LEG_NAMES):
            self._geom_code[model.geom(f"{leg}_foot").id] = i
            self._geom_code[model.geom(f"{leg}_tibia_box").id] = i if self.sense_shank else _LINK + i
            self._geom_code[model.geom(f"{leg}_coxa_box").id] = _LINK + i
            self._geom_code[model.geom(f"{leg}_femur_box").id] = _LINK + i
        self._geom_code[model.geom("body_box").id] = _BODY
        self._steps_per: dict[float, int] = {}
        self._q_target = self.q0.copy()
        self._q_target_prev = self.q0.copy()
        self._target_changed = True
        self._ff_active = False
        self._cf = np.zeros(6)
        self._force_world = np.zeros(18)
        self._body_contact = False
        self._link_contact = np.zeros(6, dtype=bool)
        self._n_steps = 0
        self._bind_readout()
        self._native = None
        self._body_id = model.body("body").id
        if self.native and not self.pushes:
            try:
                from cpgsim.robots.mujoco_native import NativeMujocoStep

                self._native = NativeMujocoStep(model, data, self._geom_code, force=self._force_world)
            except NativeUnavailable:  # no compiler or no libmujoco: Python sub-steps (slower, same results)
                self._native = None
        for _ in range(int(round(self.settle / self.time_step))):
            self._update_ctrl(self.time_step)
            self._substeps(1)
        data.time = float(t0)
        self._t = float(t0)
        self._update_outputs()

    def _touching_height(self) -> float:
        feet = foot_positions_body(self.geometry, self.q0)
        ground = np.asarray(self.terrain.height_at(feet[:, 0], feet[:, 1]), dtype=float)
        ok = np.isfinite(ground)
        if not ok.any():
            raise ModelError("no foot of the initial posture is above ground")
        return float(np.max(ground[ok] + self.geometry.leg.foot_radius - feet[ok, 2]))

    def _bind_readout(self) -> None:
        self._pos, self._vel = np.zeros(25), np.zeros(24)
        self._contact = np.zeros(1)
        self._readout_out = np.zeros(sum(n for _, n in OUTPUT_PORTS))
        fn = _readout_for(self.geometry)
        try:
            self._readout = NativeFunction(fn, [self._pos, self._vel, self._force_world, self._contact],
                                           [self._readout_out])
        except NativeUnavailable:
            def evaluate() -> None:
                self._readout_out[:] = np.asarray(fn(self._pos, self._vel, self._force_world, self._contact)).ravel()
            self._readout = evaluate

    def terminate(self) -> None:
        self._native = None
        self.model = None
        self.data = None

    # -- stepping ---------------------------------------------------------------------------------
    def _update_ctrl(self, dt: float) -> None:
        """``ctrl = q_target`` (+ ``kd/kp * dq_target/dt`` with ``velocity_ff``)."""
        if self._target_changed or self._ff_active:
            v = self.values
            ctrl = self._q_target.copy()
            if v["velocity_ff"]:
                vel = (self._q_target - self._q_target_prev) / dt
                self._ff_active = bool(np.any(vel != 0.0))
                ctrl += v["kd"] / v["kp"] * vel
            self.data.ctrl[:] = ctrl
            self._q_target_prev = self._q_target
            self._target_changed = False

    def do_step(self, t: float, dt: float) -> None:
        """Advance ``[t, t + dt]``: ``dt / time_step`` MuJoCo steps with the servo targets held."""
        if self.data is None:
            raise ModelError(f"{self.name}: do_step before setup")
        n = self._steps_for(dt)
        if abs(t - self._t) > 0.5 * self.time_step:
            raise ModelError(f"{self.name}: do_step at t = {t}, but the plant is at t = {self._t}")
        self._update_ctrl(dt)
        self._substeps(n)
        self._t = t + dt
        self._n_steps += n
        self._update_outputs()

    def _substeps(self, n: int) -> None:
        """``n`` MuJoCo steps; the contact forces averaged and the contact flags or-ed over them."""
        if self._native is not None:
            native = self._native
            native.run(n)
            self._force_world[:] = native.force
            flags = native.flags
            self._body_contact = bool(flags[0])
            self._link_contact[:] = flags[1:] > 0.5
            return
        model, data = self.model, self.data
        if n == 1 and not self.pushes:
            mujoco.mj_step(model, data)
            self._read_contacts()
            return
        total = np.zeros(18)
        body = False
        link = np.zeros(6, dtype=bool)
        for _ in range(n):
            if self.pushes:
                self._set_push_wrench()
            mujoco.mj_step(model, data)
            self._read_contacts()
            total += self._force_world
            body |= self._body_contact
            link |= self._link_contact
        if self.pushes:
            data.xfrc_applied[self._body_id] = 0.0
        self._force_world[:] = total / n
        self._body_contact = body
        self._link_contact[:] = link

    def _set_push_wrench(self) -> None:
        """The pushes active at the next MuJoCo step as the body's ``xfrc_applied``: the force at the body's
        centre of mass plus the torque of its offset from there."""
        data, b = self.data, self._body_id
        wrench = np.zeros(6)
        for push in self.pushes_at(float(data.time)):
            force = np.asarray(push.force_N)
            point = data.xpos[b] + data.xmat[b].reshape(3, 3) @ np.asarray(push.point_m)
            wrench[:3] += force
            wrench[3:] += np.cross(point - data.xipos[b], force)
        data.xfrc_applied[b] = wrench

    # -- the closed loop in C (cpgsim.harness.fused) ----------------------------------------------------
    def closed_loop(self, commit_fn: int, ctx: int, nx: int, nz: int, u: np.ndarray, y: np.ndarray,
                    u_map: list[tuple[slice, str]], inputs: dict[str, slice], yi: np.ndarray, dt: float):
        """A :class:`~cpgsim.robots.mujoco_native.FusedLoop` running this plant with a controller's bound
        compiled step (``commit_fn(ctx, t, nx, nz)``, the ``cpgsim_step_commit`` of
        :mod:`cpgsim.harness.native`) in one C loop, or None when this plant cannot (no native step,
        ``velocity_ff`` on, an input that is not ``q_target``).

        ``u_map``: which slice of the controller's input vector ``u`` takes which output port; ``inputs``:
        the slice of the controller's signals ``y`` feeding each input port; ``yi``: the recorded signals.
        """
        if (self._native is None or not isinstance(self._readout, NativeFunction) or self.values["velocity_ff"]
                or set(inputs) != {"q_target"}):
            return None
        from cpgsim.robots.mujoco_native import FusedLoop

        sl = inputs["q_target"]
        qt_idx = np.arange(sl.start, sl.stop)
        if qt_idx.size != 18:
            return None
        u_idx, o_idx = [], []
        for u_sl, port in u_map:
            o_sl = _PORT_DICT[port]
            u_idx += list(range(u_sl.start, u_sl.stop))
            o_idx += list(range(o_sl.start, o_sl.stop))
        self._dt_bound = dt
        self.output_slices = dict(_PORT_DICT)
        return FusedLoop(self, self._native, commit_fn, ctx, nx, nz, u, y, np.array(u_idx), np.array(o_idx), qt_idx,
                         np.asarray(yi))

    def _after_fused(self, steps: int, t: float | None) -> None:
        """Bring the Python side up to date after ``steps`` macro steps of the fused loop (ending at ``t``)."""
        if steps <= 0:
            return
        self._t = t
        self._n_steps += steps * self._steps_for(self._dt_bound)
        self._q_target = np.array(self.data.ctrl)
        self._q_target_prev = self._q_target
        flags = self._native.flags
        self._force_world[:] = self._native.force
        self._body_contact = bool(flags[0])
        self._link_contact[:] = flags[1:] > 0.5

    def _read_contacts(self) -> None:
        """Sum the contact forces on the robot per leg (world frame)."""
        model, data = self.model, self.data
        f = self._force_world
        f[:] = 0.0
        self._link_contact[:] = False
        body = False
        codes = self._geom_code
        cf = self._cf
        for k in range(data.ncon):
            c = data.contact[k]
            g1, g2 = int(c.geom1), int(c.geom2)
            code1, code2 = codes[g1], codes[g2]
            if code2 != _OTHER:  # the force geom1 exerts on geom2 is the force on the robot
                code, sign = code2, 1.0
            elif code1 != _OTHER:
                code, sign = code1, -1.0
            else:
                continue
            if code < _LINK:
                mujoco.mj_contactForce(model, data, k, cf)
                world = c.frame.reshape(3, 3).T @ cf[:3]
                f[3 * code:3 * code + 3] += sign * world
            elif code == _BODY:
                body = True
            else:
                self._link_contact[code - _LINK] = True
        self._body_contact = body

    def _update_outputs(self) -> None:
        self._pos[:] = self.data.qpos
        self._vel[:] = self.data.qvel
        self._contact[0] = 1.0 if self._body_contact else 0.0
        self._readout()

    def get_outputs(self) -> dict[str, np.ndarray]:
        if self.data is None:
            raise ModelError(f"{self.name}: get_outputs before setup")
        out = self._readout_out.copy()
        return {name: out[sl] for name, sl in _PORT_SLICES}

    # -- helpers (time, toe_force_world, link_contacts, body_contact, set_inputs: PlantCommon) ------

    def total_mass(self) -> float:
        """Mass of the robot in the compiled model (kg)."""
        return float(self.model.body_mass[1:].sum())

    def fell(self, max_tilt: float = math.pi / 4) -> bool:
        if self.data is None:
            return False
        if self._body_contact:
            return True
        if not np.all(np.isfinite(self.data.qpos)):
            return True
        return tilt_angle(self.data.xmat[self.model.body("body").id].reshape(3, 3)) > max_tilt


def _readout_for(geometry: RobotGeometry):
    key = repr(geometry)
    fn = _READOUTS.get(key)
    if fn is None:
        fn = _READOUTS[key] = readout_function(geometry, root="quat")
    return fn


_READOUTS: dict[str, object] = {}
_PORT_SLICES: list[tuple[str, slice]] = []
_k = 0
for _name, _size in OUTPUT_PORTS:
    _PORT_SLICES.append((_name, slice(_k, _k + _size)))
    _k += _size
_PORT_DICT = dict(_PORT_SLICES)
