"""The DART plant's world step, contact sums and state read in one C call (:class:`NativeDartStep`).

dartpy has no bulk access to a step's contacts: ``world.getLastCollisionResult()`` returns a *copy* of
the collision result (its contact vector and colliding-object sets), ``getContacts()`` builds a list of
Python ``Contact`` copies, and every ``force`` / ``collisionObject`` attribute is one more binding call
(about 1.5 us per contact, 25-50 us per step with 6-12 contacts). The dartpy wheel ships no headers, but
it exports DART's C++ symbols, so a small C file can call the same member functions the bindings call:
``MetaSkeleton::setForces``, ``World::step(true)``, ``World::getLastCollisionResult() const`` (a
reference, no copy), ``CollisionResult::getNumContacts/getContact``, ``MetaSkeleton::getPosition/
getVelocity``. The addresses of the C++ objects are those pybind11 keeps in its instances (the value
pointer after the object header), and the ``Contact`` fields read are DART's struct (``point, normal,
force`` as three ``Eigen::Vector3d``, then ``collisionObject1, collisionObject2``).

The same library holds ``cpgsim_dart_loop``, the controller + plant loop of :mod:`cpgsim.robots.dart.fused`.

Nothing here is trusted blindly: :class:`NativeDartStep` checks the world's time step and the skeleton's dof count
and positions through the C calls against the bindings, and the plant compares the C readout with its
Python readout, bit for bit, over the first steps of every set-up (:attr:`NativeDartStep.checks_left`);
any difference switches the plant back to Python for good. Collision objects are told apart by their
addresses, which the plant registers from its Python readout on first sight (the C call reports an
unknown object, and the plant reads that step's contacts in Python). The sums are the Python loop's
operations in the same order (``f += sign * force``, ``sign = +-1``), so the outputs are the same numbers.

What of dartpy's internals the C needs is in one place here: :data:`_SYMBOLS` (the exported C++ functions,
in the order of the C's ``dart_api`` struct) and :data:`LAYOUT` (the pybind11 value pointer's offset and
the offsets of ``Contact``'s fields, prepended to the C as ``#define`` lines by :func:`library_source`). When
the library loads, :func:`_load` checks them against the installed dartpy: a release in
:data:`VERIFIED_DARTPY`, every symbol exported, and a self-test (:func:`_self_test`: a box resting on the
ground, one world step, the contacts the C reads at those offsets compared bit for bit with dartpy's
``getContacts()``). Any failure raises :class:`NativeUnavailable` with one line naming dartpy's version and
what did not match; the plant warns with it and keeps its Python loop (as ``native=False``).

The plant's ``native=False`` (a scenario's ``robot.native = false``) keeps its Python loop (benchmarks
compare the two in one process).
"""

from __future__ import annotations

import ctypes

import dartpy as dart
import numpy as np

from cpgsim.harness.c.toolchain import NativeUnavailable, Prototypes, c_source, compile_source, declare

_SYMBOLS = {  # the C name of each function pointer (the dart_api struct's order) -> dartpy's DART 6 C++ symbol
    "world_step": "_ZN4dart10simulation5World4stepEb",
    "world_time_step": "_ZNK4dart10simulation5World11getTimeStepEv",
    "world_result": "_ZNK4dart10simulation5World22getLastCollisionResultEv",
    "num_contacts": "_ZNK4dart9collision15CollisionResult14getNumContactsEv",
    "get_contact": "_ZNK4dart9collision15CollisionResult10getContactEm",
    "set_forces": "_ZN4dart8dynamics12MetaSkeleton9setForcesERKN5Eigen6MatrixIdLin1ELi1ELi0ELin1ELi1EEE",
    "get_position": "_ZNK4dart8dynamics12MetaSkeleton11getPositionEm",
    "get_velocity": "_ZNK4dart8dynamics12MetaSkeleton11getVelocityEm",
    "num_dofs": "_ZNK4dart8dynamics8Skeleton10getNumDofsEv",
}

LAYOUT = {
    # pybind11's instance: the value pointer right after the Python object header (ob_refcnt, ob_type)
    "pybind_value": ctypes.sizeof(ctypes.c_ssize_t) + ctypes.sizeof(ctypes.c_void_p),
    # dart::collision::Contact: point, normal, force (Eigen::Vector3d each), collisionObject1, collisionObject2
    "contact_force": 48,
    "contact_object1": 72,
    "contact_object2": 80,
}
"""Byte offsets the C step assumes in dartpy's objects (checked at load by :func:`_self_test`)."""

_vp, _int, _dbl = ctypes.c_void_p, ctypes.c_int, ctypes.c_double
_dp, _ip, _lp = ctypes.POINTER(ctypes.c_double), ctypes.POINTER(ctypes.c_int), ctypes.POINTER(ctypes.c_longlong)

PROTOTYPES: Prototypes = {  # return types as ctypes had them (int where none was set and the C returns int)
    "cpgsim_dart_bind": (_vp, [ctypes.POINTER(_vp), _vp, _vp, _dp, _dp, _vp, _dp, _dp, _dp, ctypes.c_size_t, _vp, _vp]),
    "cpgsim_dart_unbind": (None, [_vp]),
    "cpgsim_dart_register": (_int, [_vp, _vp, _int]),
    "cpgsim_dart_time_step": (_dbl, [_vp]),
    "cpgsim_dart_num_dofs": (ctypes.c_size_t, [_vp]),
    "cpgsim_dart_outputs": (_int, [_vp, _int]),
    "cpgsim_dart_step": (_int, [_vp]),
    "cpgsim_dart_loop": (_int, [_vp, _vp, _vp, _int, _int, _dp, _dp, _int, _lp, _lp, _dp, _int, _lp, _dp, _ip,
                                _dbl, _int, _lp, _dp, _dp, _int, _int, _dp, _ip]),
    "cpgsim_dart_probe": (ctypes.c_size_t, [ctypes.POINTER(_vp), _vp, ctypes.c_size_t, _dp, ctypes.POINTER(_vp),
                                            ctypes.POINTER(_vp), _dp]),
    "cpgsim_dart_step_seconds": (_dbl, [_vp]),
    "cpgsim_dart_step_count": (ctypes.c_long, [_vp]),
    "cpgsim_dart_ctrl_seconds": (_dbl, [_vp]),
    "cpgsim_dart_loop_seconds": (_dbl, [_vp]),
}

SOURCE = c_source(__package__, "c/dart_loop.c")
"""The world step, contact sums and fused loop, calling DART through the pointer table of ``_SYMBOLS``
(without the ``Contact`` offsets: :func:`library_source` is what compiles)."""


def library_source() -> str:
    """:data:`SOURCE` after the ``#define CPGSIM_DART_CONTACT_*`` offsets of :data:`LAYOUT`."""
    defines = "".join(f"#define CPGSIM_DART_{key.upper()} {value}\n" for key, value in LAYOUT.items()
                      if key.startswith("contact_"))
    return defines + SOURCE


def address(obj: object) -> int:
    """The C++ object a pybind11 wrapper holds (its value pointer, right after the Python object header)."""
    return ctypes.c_void_p.from_address(id(obj) + LAYOUT["pybind_value"]).value or 0


_LIB: ctypes.PyDLL | None = None
_FNS: ctypes.Array | None = None
_FAILED: NativeUnavailable | None = None  # why the library is unavailable in this process (tried once)


def _library() -> tuple[ctypes.PyDLL, ctypes.Array]:
    """The compiled C (cached) and the table of DART function pointers, once per process (a failure too)."""
    global _FAILED
    if _FAILED is not None:
        raise _FAILED
    try:
        return _load()
    except NativeUnavailable as exc:
        _FAILED = exc
        raise


VERIFIED_DARTPY = ("6.20.",)
"""dartpy releases whose object layouts (pybind11's instance, DART's ``Contact``) the C step was checked
against. The set-up checks would catch most mismatches, but a wrong object address could crash before a
check sees it, so other releases keep the Python loop (same numbers, slower)."""


def _load() -> tuple[ctypes.PyDLL, ctypes.Array]:
    """Check the installed dartpy against :data:`_SYMBOLS` and :data:`LAYOUT`, compile, self-test, load."""
    global _LIB, _FNS
    if _LIB is None:
        version = getattr(dart, "__version__", "") or "(unknown version)"
        if not version.startswith(VERIFIED_DARTPY):
            raise NativeUnavailable(f"dartpy {version}: the C step was verified on "
                                    f"dartpy {', '.join(v + 'x' for v in VERIFIED_DARTPY)} only")
        try:
            dart_lib = ctypes.CDLL(dart.__file__)
        except OSError as exc:
            raise NativeUnavailable(f"dartpy {version}: its library does not load with ctypes: {exc}") from exc
        missing = [name for name, sym in _SYMBOLS.items() if not hasattr(dart_lib, sym)]
        if missing:
            raise NativeUnavailable(f"dartpy {version} does not export the DART symbols the C step needs: "
                                    + ", ".join(f"{name} ({_SYMBOLS[name]})" for name in missing))
        fns = (ctypes.c_void_p * len(_SYMBOLS))(
            *[ctypes.cast(dart_lib[sym], ctypes.c_void_p).value for sym in _SYMBOLS.values()])
        # PyDLL: the calls keep the GIL, as dartpy's world.step() does (no two DART worlds step at once on
        # threads of one process, as before)
        lib = ctypes.PyDLL(str(compile_source(library_source(), "cpgsim_dart", origin="robots/dart/c/dart_loop.c")))
        declare(lib, PROTOTYPES)
        mismatch = _self_test(lib, fns)
        if mismatch:
            raise NativeUnavailable(f"dartpy {version}: the C step's view of DART does not match the bindings': "
                                    f"{mismatch}")
        _LIB, _FNS = lib, fns
    return _LIB, _FNS  # type: ignore[return-value]


def _box_world() -> dart.simulation.World:
    """A 1 kg box of 0.2 m resting (0.5 mm deep) on an immobile ground box: four contacts every step."""
    world = dart.simulation.World()
    world.setTimeStep(1e-3)
    for name, size, z, mobile in (("ground", [2.0, 2.0, 0.2], -0.1, False), ("box", [0.2, 0.2, 0.2], 0.0995, True)):
        skel = dart.dynamics.Skeleton(f"cpgsim_self_test_{name}")
        joint, body = (skel.createFreeJointAndBodyNodePair() if mobile else skel.createWeldJointAndBodyNodePair())
        node = body.createShapeNode(dart.dynamics.BoxShape(size))
        node.createCollisionAspect()
        node.createDynamicsAspect()
        if mobile:
            body.setMass(1.0)
            skel.setPosition(5, z)
        else:
            T = dart.math.Isometry3()
            T.set_identity()
            T.set_translation([0.0, 0.0, z])
            joint.setTransformFromParentBodyNode(T)
            skel.setMobile(False)
        world.addSkeleton(skel)
    return world


def _self_test(lib: ctypes.PyDLL, fns: ctypes.Array) -> str | None:
    """One world step of :func:`_box_world`, its contacts read by the C (``cpgsim_dart_probe``, at the
    :data:`LAYOUT` offsets) and by dartpy's ``getContacts()``: None when they agree bit for bit, else what
    differed (one line).

    The object header is checked first (the C follows the world's address; the contacts' fields are only
    read, the objects they name are compared by address, never followed).
    """
    if LAYOUT["pybind_value"] != object.__basicsize__:
        return (f"pybind11's value pointer at offset {LAYOUT['pybind_value']}, after a Python object header of "
                f"{object.__basicsize__} bytes")
    world = _box_world()
    world.step()
    contacts = world.getLastCollisionResult().getContacts()
    if not contacts:
        return "no contact between the self-test's box and the ground"
    max_n = 64
    force = np.zeros((max_n, 3))
    obj1, obj2 = (ctypes.c_void_p * max_n)(), (ctypes.c_void_p * max_n)()
    time_step = ctypes.c_double()
    n = lib.cpgsim_dart_probe(fns, address(world), max_n, force.ctypes.data_as(ctypes.POINTER(ctypes.c_double)),
                              obj1, obj2, ctypes.byref(time_step))
    if time_step.value != world.getTimeStep():
        return f"World::getTimeStep gives {time_step.value!r} where the bindings give {world.getTimeStep()!r}"
    if n != len(contacts):
        return f"CollisionResult::getNumContacts gives {n} where getContacts() lists {len(contacts)}"
    for i, c in enumerate(contacts):
        if force[i].tobytes() != np.asarray(c.force, dtype=np.float64).tobytes():
            return (f"Contact.force at offset {LAYOUT['contact_force']} reads {force[i].tolist()} where "
                    f"getContacts() says {np.asarray(c.force).tolist()}")
        for key, got, obj in (("contact_object1", obj1[i], c.collisionObject1),
                              ("contact_object2", obj2[i], c.collisionObject2)):
            if (got or 0) != address(obj):
                return (f"Contact.{key[8:].replace('object', 'collisionObject')} at offset {LAYOUT[key]} reads "
                        f"{got or 0:#x} where the bindings' object is at {address(obj):#x}")
    return None


class NativeDartStep:
    """One set-up plant's world, skeleton and buffers bound to the C step (see the module docstring).

    ``step()`` runs one world step and returns the C status (0, 2 with body contact, 1 an unregistered
    collision object met: contacts and outputs not read, -1 the readout failed); ``register(obj, code)``
    tells the C which code a collision object (a dartpy wrapper) has. The arrays passed in must stay the plant's
    buffers (written in place) for the binding's life; :meth:`close` before the world goes.
    """

    CHECK_STEPS = 50
    """Steps of each set-up whose C readout is compared with the Python readout."""

    def __init__(self, world, skel, forces: np.ndarray, force_world: np.ndarray, link: np.ndarray,
                 pos: np.ndarray, vel: np.ndarray, contact: np.ndarray, readout: tuple[int, int] | None) -> None:
        self._ctx = None
        lib, fns = _library()
        n = skel.getNumDofs()
        for arr, size, dtype in ((forces, n, np.float64), (force_world, 18, np.float64), (link, 6, np.bool_),
                                 (pos, n, np.float64), (vel, n, np.float64), (contact, 1, np.float64)):
            if arr.dtype != dtype or arr.size != size or not arr.flags.c_contiguous:
                raise ValueError(f"buffer of {arr.size} {arr.dtype} does not fit the C step")
        self._lib, self._keep = lib, (world, skel, forces, force_world, link, pos, vel, contact)
        feval, fctx = readout if readout is not None else (None, None)
        self._ctx = lib.cpgsim_dart_bind(
            fns, address(world), address(skel), forces.ctypes.data_as(ctypes.POINTER(ctypes.c_double)),
            force_world.ctypes.data_as(ctypes.POINTER(ctypes.c_double)), link.ctypes.data,
            pos.ctypes.data_as(ctypes.POINTER(ctypes.c_double)), vel.ctypes.data_as(ctypes.POINTER(ctypes.c_double)),
            contact.ctypes.data_as(ctypes.POINTER(ctypes.c_double)), n, feval, fctx)
        if not self._ctx:
            raise MemoryError("cpgsim_dart_bind: allocation failed")
        self.step = lambda _f=lib.cpgsim_dart_step, _c=self._ctx: _f(_c)
        self.checks_left = self.CHECK_STEPS
        if lib.cpgsim_dart_time_step(self._ctx) != world.getTimeStep() or lib.cpgsim_dart_num_dofs(self._ctx) != n:
            self.close()
            raise NativeUnavailable("the C step does not see this dartpy's world and skeleton as the bindings do")
        if lib.cpgsim_dart_outputs(self._ctx, 0) or not (np.array_equal(pos, skel.getPositions())
                                                         and np.array_equal(vel, skel.getVelocities())):
            self.close()  # (the plant reads its outputs again after this)
            raise NativeUnavailable("the C step reads other positions than the bindings")

    @property
    def library(self) -> ctypes.CDLL:
        """The compiled library (its ``cpgsim_dart_loop`` is the fused loop's)."""
        return self._lib

    @property
    def context(self):
        """The bound C context (the world, the skeleton and the plant's buffers)."""
        return self._ctx

    def step_time(self) -> tuple[float, int, float]:
        """Seconds spent inside ``World::step`` by :meth:`step`, the number of those steps, and the seconds
        spent in the controller's step by the closed loop (``cpgsim_dart_loop``): for benchmarks."""
        return (self._lib.cpgsim_dart_step_seconds(self._ctx), self._lib.cpgsim_dart_step_count(self._ctx),
                self._lib.cpgsim_dart_ctrl_seconds(self._ctx))

    def loop_time(self) -> float:
        """Seconds spent inside the closed loop's C calls (``cpgsim_dart_loop``), for benchmarks."""
        return self._lib.cpgsim_dart_loop_seconds(self._ctx)

    def register(self, obj, code: int) -> None:
        """The collision object ``obj`` (a dartpy wrapper) has the plant's ``code``."""
        if self._lib.cpgsim_dart_register(self._ctx, address(obj), code):
            raise NativeUnavailable("more collision objects than the C step holds")

    def close(self) -> None:
        if self._ctx:
            self._lib.cpgsim_dart_unbind(self._ctx)
            self._ctx = None
            self.step = None  # type: ignore[assignment]

    def __del__(self) -> None:
        self.close()
