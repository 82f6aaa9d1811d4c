"""What the hexapod plant of every engine shares: one class an engine's plant derives from.

:class:`HexapodPlant` holds the engine-neutral part of the plant block (Yu 2019, Sec. 5: the servos track
the joint targets of the CPG's linear converter; Fukuhara 2022 reads the vertical toe forces): the
constructor arguments every engine takes, the parameters and ports (:mod:`cpgsim.robots.ports`), taking the
joint targets, the macro step (world steps per macro step, the toe forces averaged and the contact flags
or-ed over them, the pushes each step covers, the settle phase), the servo law, the compiled readout bound on
:class:`PlantBuffers`, the outputs, the fall test, pushes and amputated legs, and the fused-loop request's
indices. An engine's plant supplies the rest (the engine contract, docs/architecture.md):

- ``setup(t0)``: build the engine's model of the robot on the terrain, place it, set the
  servos; fill the buffers' ``pos``/``vel`` as :meth:`HexapodPlant.state_layout` says (``READOUT_ROOT`` names
  the root joint's coordinates; override ``state_layout`` when the joints are not the rigid robot's); then
  :meth:`HexapodPlant._settle` and the first outputs;
- ``_apply_servo(q_target, velocity)``: the servo law's targets onto the engine's actuators;
- ``_world_step(pushes)``: one engine step with the servo inputs held and the pushes on the body;
- ``_robot_contacts()``, ``_contact_force(contact)``: the last engine step's contacts that touch the robot
  (its shape's code, the force's sign) and a contact's force (world frame), for :meth:`HexapodPlant.read_contacts`;
- ``_native_steps(n, t)`` (optional): ``n`` engine steps from ``t`` through the engine's C step;
- ``_read_state()``: the engine's generalized positions and velocities into the buffers;
- ``_body_rotation()``, ``_state_finite()``: for :meth:`HexapodPlant.fell`;
- for the capabilities ``snapshot_restore`` and ``fused_loop``: also derive
  :class:`~cpgsim.harness.cosim.contracts.ResumableBlock` (``snapshot``/``restore``; ``resume_from`` is here) and
  :class:`~cpgsim.harness.cosim.contracts.FusedLoopBlock` (``fused_loop``); an engine that does not declare them
  does not derive them, so the master never asks it (and :func:`cpgsim.robots.registry.require` refuses a
  run that needs them, naming the engine).

Every capability an engine declares in the registry (:mod:`cpgsim.robots.registry`) it implements here;
the contract tests (tests/test_plant_contract.py) run the same checks on every registered engine.
"""

from __future__ import annotations

import math
import struct
from abc import ABC, abstractmethod
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from cpgsim.components.core import CoSimBlock, ModelError, ParameterError
from cpgsim.components.geometry import RobotGeometry
from cpgsim.harness.native import NativeFunction, NativeUnavailable
from cpgsim.robots.description import CONTACT_BODY, CONTACT_LINK, FALL_TILT_DEG, AnkleSpring, fallen, tilt_angle
from cpgsim.robots.disturbance import Push, active_pushes, as_pushes
from cpgsim.robots.ports import PORT_SLICES, READOUT_SIZE, declare_plant
from cpgsim.robots.readout import StateLayout, readout_function
from cpgsim.robots.terrain import Terrain, flat


@dataclass
class PlantBuffers:
    """The arrays a plant's readout (and its C step, and its fused loop) reads and writes in place.

    ``pos``, ``vel``: the engine's generalized positions and velocities (the root joint's, then the 18
    joints); ``force_world``: per leg the ground force on the foot, world frame (18); ``contact``: the body
    contact flag as a number (1); ``link_contact``: per leg, a coxa or femur (or unsensed tibia) touched
    something (6, bool); ``out``: the readout vector, the output ports in ``OUTPUT_PORTS`` order."""

    pos: np.ndarray
    vel: np.ndarray
    force_world: np.ndarray = field(default_factory=lambda: np.zeros(18))
    contact: np.ndarray = field(default_factory=lambda: np.zeros(1))
    link_contact: np.ndarray = field(default_factory=lambda: np.zeros(6, dtype=bool))
    out: np.ndarray = field(default_factory=lambda: np.zeros(READOUT_SIZE))


class HexapodPlant(CoSimBlock, ABC):
    """The hexapod on a terrain, stepped by the co-simulation master; an engine's plant derives from it.

    Constructor arguments every engine takes (fixed for the block's life; parameters go in ``**params``):

    - ``geometry``: a :class:`~cpgsim.components.geometry.RobotGeometry`;
    - ``terrain``: a :class:`~cpgsim.robots.terrain.Terrain` (default flat ground);
    - ``q0``: initial joint angles (18, rad; default :func:`~cpgsim.robots.description.standing_posture`);
    - ``body_height``: initial height of the body frame (m); default: the lowest foot sphere just touches
      the ground under it (body level, at the world origin, facing ``+y``);
    - ``sense_shank``: count tibia contacts as toe forces (default ``True``);
    - ``settle``: seconds simulated in :meth:`setup` with the targets held at ``q0`` before the clock is set
      to ``t0`` (so ``t0``'s outputs show a loaded, resting robot); default 0;
    - ``disturbances``: pushes on the body (:class:`~cpgsim.robots.disturbance.Push` or mappings with
      ``start_s``, ``duration_s``, ``force_N`` in the world frame, ``point_m`` in the body frame), applied
      at every engine step they cover;
    - ``amputated``: leg indices whose links touch nothing (Fukuhara 2022, Sec. 3.2: they keep their mass
      and are held folded by the controller);
    - ``ankle``: a compliant ankle on every leg (:class:`~cpgsim.robots.description.AnkleSpring`, or a mapping
      with ``stiffness`` N/m and ``damping`` N s/m; Yu 2019's prototype, Sec. 6.2.1), read at set-up;
      default None, the foot rigid on the tibia.

    Parameters: ``kp`` (N m/rad), ``kd`` (N m s/rad), ``friction`` (Coulomb coefficient of the robot's
    shapes; the ground has its terrain's), ``velocity_ff`` (0/1).
    """

    engine: ClassVar[str]
    READOUT_ROOT: ClassVar[str]

    time_step: float
    buffers: PlantBuffers
    native_step: object | None

    def __init__(self, name: str, geometry: RobotGeometry, terrain: Terrain | None, q0: Sequence[float] | None,
                 body_height: float | None, sense_shank: bool, settle: float,
                 disturbances: Sequence[Push | Mapping] | None, amputated: Sequence[int],
                 ankle: AnkleSpring | Mapping | None = None, **params: float) -> None:
        from cpgsim.robots.description import standing_posture

        self.name = name
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
        try:
            self.amputated = tuple(sorted({int(i) for i in amputated}))
        except (TypeError, ValueError):
            raise ParameterError(f"amputated must be leg indices 0-5, got {amputated!r}") from None
        if any(not 0 <= i < 6 for i in self.amputated):
            raise ParameterError(f"amputated legs must be leg indices 0-5, got {self.amputated}")
        self.ankle = ankle
        self._q_target = q0_arr.copy()
        self._resume = None
        self.last_snapshot = None
        super().__init__(name, **params)

    # -- declaration ------------------------------------------------------------------------------
    def declare(self) -> None:
        declare_plant(self)

    # -- inputs and steps -------------------------------------------------------------------------
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

    def steps_for(self, dt: float) -> int:
        """Engine steps per macro step ``dt`` (a whole number, or an error naming the plant)."""
        n = self._steps_per.get(dt)
        if n is None:
            n = engine_steps(dt, self.time_step)
            if n is None:
                raise ModelError(f"{self.name}: dt = {dt} is not a positive multiple of the world step "
                                 f"{self.time_step}")
            self._steps_per[dt] = n
        return n

    # -- the macro step (the same in every engine) ---------------------------------------------------
    def do_step(self, t: float, dt: float) -> None:
        """Advance ``[t, t + dt]``: ``dt / time_step`` engine steps with the servo targets held (the engine's C
        step when it has one and can take this step, else :meth:`_python_steps`), then the outputs."""
        self._check_step(t)
        n = self.steps_for(dt)
        self._update_servo(dt)
        if self.native_step is None or not self._native_steps(n, t):
            self._python_steps(t, n)
            self.update_outputs()
        self._t = t + dt
        self._n_steps += n

    def _python_steps(self, t: float, n: int) -> None:
        """``n`` engine steps from ``t`` in Python, each with the pushes it covers; the toe forces are the mean
        over the steps and the contact flags are set when any step saw the contact (what a macro step longer
        than the engine step reports)."""
        if n == 1 and not self.pushes:
            self._world_step(())
            self.read_contacts()
            return
        h = self.time_step
        total = np.zeros(18)
        body = False
        link = np.zeros(6, dtype=bool)
        for i in range(n):
            self._world_step(self.pushes_at(t + i * h))
            self.read_contacts()
            total += self._force_world
            body |= self._body_contact
            link |= self._link_contact
        self._force_world[:] = total / n
        self._body_contact = body
        self._link_contact[:] = link  # in place: a C step holds this buffer

    def _settle(self, seconds: float) -> None:
        """Simulate ``seconds`` with the targets held at ``q0`` before the clock starts (no pushes: they are
        timed from ``t0``)."""
        for _ in range(int(round(seconds / self.time_step))):
            self._update_servo(self.time_step)
            if self.native_step is None or not self._native_steps(1):
                self._world_step(())
                self.read_contacts()

    def _native_steps(self, n: int, t: float | None = None) -> bool:
        """``n`` engine steps through the engine's C step, the first starting at ``t`` (the pushes it covers act;
        None: none act, as in the settle phase), leaving the contact readings and the outputs current; False
        (nothing done) when the C step cannot take this macro step."""
        return False

    @abstractmethod
    def _world_step(self, pushes: Sequence[Push]) -> None:
        """One engine step with the servo inputs held and ``pushes`` on the body."""
        raise NotImplementedError

    def read_contacts(self) -> None:
        """The last engine step's contacts into the buffers, by the code of the robot's shape in each
        (:meth:`cpgsim.robots.description.ShapeSpec.contact_code`): a sensed toe's force is added to its leg's
        sum (world frame, the force on the robot), a body contact sets the body flag, any other link's sets its
        leg's link flag; contacts between two shapes that are not the robot's are not read."""
        f = self._force_list
        f[:] = _ZEROS18
        body = False
        link = self._link_contact
        link[:] = False
        for code, sign, contact in self._robot_contacts():
            if code < CONTACT_LINK:
                f0, f1, f2 = self._contact_force(contact)
                k = 3 * code
                f[k] += sign * f0
                f[k + 1] += sign * f1
                f[k + 2] += sign * f2
            elif code == CONTACT_BODY:
                body = True
            else:
                link[code - CONTACT_LINK] = True  # a coxa/femur (or unsensed shank) touched something
        _PACK18(self._force_bytes, 0, *f)  # 0.25 us; a numpy slice assignment from a list takes 0.8
        self._body_contact = body

    @abstractmethod
    def _robot_contacts(self) -> Iterable[tuple[int, float, Any]]:
        """``(code, sign, contact)`` for each contact of the last engine step that touches the robot: the code
        of the robot's shape in it, ``sign`` +1 when the engine's contact force acts on that shape and -1 when
        it acts on the other one, and what :meth:`_contact_force` reads the force from."""
        raise NotImplementedError

    @abstractmethod
    def _contact_force(self, contact: Any) -> Sequence[float]:
        """A contact's force in the world frame (3 floats), signed as the engine reports it."""
        raise NotImplementedError

    # -- the servo law (Yu 2019, Sec. 5) -------------------------------------------------------------
    def _update_servo(self, dt: float) -> None:
        """The servos' inputs for the next engine steps, when the targets changed (or a moving target is fed
        forward). Every engine applies one law per joint,

            ``tau = -kp (q + h qd - q_target) - kd qd  [+ kd dq_target/dt with velocity_ff]``,

        ``h`` the engine step (its spring part integrated implicitly, as DART does its joint springs), the
        target velocity a backward difference of the held targets over the macro step ``dt``. The engine's
        :meth:`_apply_servo` maps the targets (and that velocity, or None) onto its actuators."""
        if self._target_changed or self._ff_active:
            velocity = None
            if self.values["velocity_ff"]:
                velocity = (self._q_target - self._q_target_prev) / dt
                self._ff_active = bool(np.any(velocity != 0.0))
            self._apply_servo(self._q_target, velocity)
            self._q_target_prev = self._q_target
            self._target_changed = False

    @abstractmethod
    def _apply_servo(self, q_target: np.ndarray, velocity: np.ndarray | None) -> None:
        """Set the engine's servo inputs for the law of :meth:`_update_servo`."""
        raise NotImplementedError

    def _check_step(self, t: float) -> None:
        if not self.is_set_up:
            raise ModelError(f"{self.name}: do_step before setup")
        if abs(t - self._t) > 0.5 * self.time_step:
            raise ModelError(f"{self.name}: do_step at t = {t}, but the plant is at t = {self._t}")

    @property
    @abstractmethod
    def is_set_up(self) -> bool:
        raise NotImplementedError

    @property
    def time(self) -> float:
        return self._t

    def _reset_readings(self) -> None:
        """The per-run state every engine keeps between steps, as at the start of a set-up."""
        self._steps_per: dict[float, int] = {}
        self._q_target = self.q0.copy()
        self._q_target_prev = self.q0.copy()
        self._target_changed = True
        self._ff_active = False
        self._body_contact = False
        self._n_steps = 0

    # -- pushes -----------------------------------------------------------------------------------
    def set_disturbances(self, disturbances: Sequence[Push | Mapping] | None) -> None:
        """Replace the pushes (as the constructor's ``disturbances``); from the next :meth:`setup` on."""
        self.pushes = as_pushes(disturbances, f"{self.name}: disturbances")

    def pushes_at(self, t: float) -> list[Push]:
        """The pushes (:mod:`cpgsim.robots.disturbance`) an engine step starting at ``t`` feels."""
        return active_pushes(self.pushes, t, self.time_step) if self.pushes else []

    @property
    def ankle(self) -> AnkleSpring | None:
        """The compliant ankle of every leg (None: rigid feet); set it before :meth:`setup`."""
        return self._ankle

    @ankle.setter
    def ankle(self, value: AnkleSpring | Mapping | None) -> None:
        if value is None or isinstance(value, AnkleSpring):
            self._ankle = value
        elif isinstance(value, Mapping):
            if set(value) != {"stiffness", "damping"}:
                raise ParameterError(f"{self.name}: ankle needs exactly stiffness (N/m) and damping (N s/m), "
                                     f"got {', '.join(sorted(value)) or 'nothing'}")
            self._ankle = AnkleSpring(**value)
        else:
            raise ParameterError(f"{self.name}: ankle must be an AnkleSpring or a mapping, got {type(value).__name__}")

    def state_layout(self) -> StateLayout:
        """Where the 18 joints (and the ankles' slides) sit in the engine's ``pos``/``vel`` (set-up plant)."""
        return StateLayout.rigid(self.READOUT_ROOT)

    # -- readout and outputs ----------------------------------------------------------------------
    def _bind_readout(self) -> None:
        """The compiled sensor readout (:mod:`cpgsim.robots.readout`) on fresh :class:`PlantBuffers`."""
        layout = self.state_layout()
        b = self.buffers = PlantBuffers(np.zeros(layout.pos_size), np.zeros(layout.vel_size))
        self._force_world, self._link_contact, self._contact = b.force_world, b.link_contact, b.contact
        self._pos, self._vel, self._readout_out = b.pos, b.vel, b.out
        self._force_list = [0.0] * 18  # read_contacts' sums, packed into force_world at once
        self._force_bytes = memoryview(b.force_world).cast("B")
        fn = readout_for(self.geometry, self.READOUT_ROOT, layout)
        try:
            self.readout = NativeFunction(fn, [b.pos, b.vel, b.force_world, b.contact], [b.out])
        except NativeUnavailable:  # no C compiler: CasADi's VM evaluates the same function (slower)
            def evaluate() -> None:
                b.out[:] = np.asarray(fn(b.pos, b.vel, b.force_world, b.contact)).ravel()
            self.readout = evaluate

    @property
    def compiled_readout(self) -> NativeFunction | None:
        """The readout as compiled C (what a C step or fused loop calls), None in CasADi's VM."""
        return self.readout if isinstance(self.readout, NativeFunction) else None

    @abstractmethod
    def _read_state(self) -> None:
        raise NotImplementedError

    def update_outputs(self) -> None:
        """The output ports from the engine's state and the summed contacts (compiled readout, about 1 us)."""
        self._read_state()
        self._contact[0] = 1.0 if self._body_contact else 0.0
        self.readout()

    def get_outputs(self) -> dict[str, np.ndarray]:
        if not self.is_set_up:
            raise ModelError(f"{self.name}: get_outputs before setup")
        out = self._readout_out.copy()  # the next do_step overwrites the bound buffer
        return {name: out[sl] for name, sl in PORT_SLICES.items()}

    output_slices = PORT_SLICES

    def toe_force_world(self) -> np.ndarray:
        """Per-leg ground force on the foot in the world frame of the last step, shape (6, 3)."""
        return self._force_world.reshape(6, 3).copy()

    def link_contacts(self) -> np.ndarray:
        """Per leg, whether a coxa or femur (or an unsensed tibia) touched something in the last step."""
        return self._link_contact.copy()

    def body_contact(self) -> bool:
        """Whether the body box touched anything in the last step."""
        return bool(self._body_contact)

    def _touching_height(self, feet: np.ndarray) -> float:
        from cpgsim.robots.description import touching_height

        return touching_height(self.geometry, self.terrain.height_at, feet)

    # -- the fall test ----------------------------------------------------------------------------
    @abstractmethod
    def _body_rotation(self) -> np.ndarray:
        raise NotImplementedError

    @abstractmethod
    def _state_finite(self) -> bool:
        raise NotImplementedError

    def fell(self, max_tilt: float = math.radians(FALL_TILT_DEG)) -> bool:
        """The robot has fallen (:func:`cpgsim.robots.description.fallen`: the body touched anything or tilted
        past ``max_tilt``, rad), or its state is not finite."""
        if not self.is_set_up:
            return False
        if not self._state_finite():
            return True
        tilt = math.degrees(tilt_angle(self._body_rotation()))
        return bool(fallen(tilt, self._body_contact, math.degrees(max_tilt)))

    # -- exact state (ResumableBlock) ---------------------------------------------------------------
    def resume_from(self, snap) -> None:
        """Make the next :meth:`setup` start in ``snap`` (no settling) instead of the initial posture."""
        self._resume = snap

    def _take_resume(self, t0: float):
        """The snapshot to start from (checked against ``t0``), consumed; None: start from ``q0``."""
        resume, self._resume = self._resume, None
        if resume is not None and abs(resume.t - float(t0)) > 0.5 * self.time_step:
            raise ModelError(f"{self.name}: resuming a state saved at t = {resume.t} in a run from t0 = {t0}")
        return resume

    def execution_info(self) -> dict[str, Any]:
        """The engine and whether its C step runs (``native`` asked for it; it may be unavailable)."""
        return {"engine": self.engine, "native_step": self.native_step is not None}

    @property
    def servo_state(self) -> tuple[np.ndarray, bool]:
        """``(q_target, target_changed)``: the targets the servos hold and whether the next step must apply
        them (what a fused loop starts from)."""
        return self._q_target, self._target_changed

    def take_fused_steps(self, t: float, q_target: np.ndarray, target_changed: bool) -> None:
        """The plant's Python side brought up to date after a fused loop stepped it to ``t``: the clock, the
        engine steps counted, the servo targets it holds (``target_changed``: the next step must apply them
        again) and the last step's contact readings (:meth:`_take_c_readings`). The one callback every
        engine's fused loop calls after each of its C calls that stepped the plant."""
        self._n_steps += int(round((t - self._t) / self.time_step))
        self._t = float(t)
        self._q_target = np.array(q_target, dtype=float)
        self._q_target_prev = self._q_target
        self._target_changed = bool(target_changed)
        self._take_c_readings()

    def _take_c_readings(self) -> None:
        """The contact readings the engine's C code left (after a fused loop's call, or a C step that does not
        write every buffer itself): by default force and link contacts are in the buffers already and the
        body flag is the readout's input."""
        self._body_contact = bool(self._contact[0])

    def _fused_refusal(self, request) -> bool:
        """What every engine's fused loop needs and this set-up lacks: a compiled readout, ``velocity_ff``
        off, no pushes."""
        return self.compiled_readout is None or bool(self.values["velocity_ff"]) or bool(self.pushes)


def engine_steps(dt: float, h: float) -> int | None:
    """Engine steps of ``h`` in a macro step ``dt``: a positive whole number, or None when ``h`` does not divide
    ``dt`` (to a relative 1e-9). The one rule for :meth:`HexapodPlant.steps_for` and for a scenario's step."""
    n = int(round(dt / h))
    return n if n >= 1 and abs(n * h - dt) <= 1e-9 * max(1.0, dt) else None


def readout_for(geometry: RobotGeometry, root: str, layout: StateLayout | None = None):
    """The readout function of a geometry, root-joint coordinates and state layout (built once per process)."""
    layout = layout or StateLayout.rigid(root)
    key = (repr(geometry), root, layout)
    fn = _READOUTS.get(key)
    if fn is None:
        fn = _READOUTS[key] = readout_function(geometry, root=root, layout=layout)
    return fn


_READOUTS: dict[tuple[str, str, StateLayout], object] = {}
_ZEROS18 = [0.0] * 18
_PACK18 = struct.Struct("18d").pack_into
