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

``CPGSIM_DART_NATIVE=0`` keeps the plant's Python loop (benchmarks compare the two in one process).
"""

from __future__ import annotations

import ctypes
import os

import dartpy as dart
import numpy as np

from cpgsim.harness.toolchain import NativeUnavailable, Prototypes, c_source, compile_source, declare

_SYMBOLS = {  # the C name of each function pointer -> the exported C++ symbol of dartpy's DART 6
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
    "cpgsim_dart_loop": (_int, [_vp, _vp, _vp, _int, _int, _dp, _dp, _int, _lp, _lp, _dp, _int, _lp, _dp, _ip, _ip,
                                _dbl, _int, _lp, _dp, _dp, _int, _int, _dp, _ip]),
    "cpgsim_dart_step_seconds": (_dbl, [_vp]),
    "cpgsim_dart_step_count": (ctypes.c_long, [_vp]),
    "cpgsim_dart_ctrl_seconds": (_dbl, [_vp]),
    "cpgsim_dart_loop_seconds": (_dbl, [_vp]),
}

SOURCE = c_source(__package__, "c/dart_loop.c")
"""The world step, contact sums and fused loop, calling DART through the pointer table of ``_SYMBOLS``."""


def enabled() -> bool:
    """The C step is used unless ``CPGSIM_DART_NATIVE=0``."""
    return os.environ.get("CPGSIM_DART_NATIVE", "1") != "0"


def address(obj: object) -> int:
    """The C++ object a pybind11 wrapper holds (its value pointer, right after the Python object header)."""
    return ctypes.c_void_p.from_address(id(obj) + _HEADER).value or 0


_HEADER = ctypes.sizeof(ctypes.c_ssize_t) + ctypes.sizeof(ctypes.c_void_p)  # ob_refcnt, ob_type
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
    global _LIB, _FNS
    if _LIB is None:
        version = getattr(dart, "__version__", "")
        if not version.startswith(VERIFIED_DARTPY):
            raise NativeUnavailable(f"dartpy {version or '(unknown version)'}: the C step was verified on "
                                    f"dartpy {', '.join(v + 'x' for v in VERIFIED_DARTPY)} only")
        try:
            dart_lib = ctypes.CDLL(dart.__file__)
            fns = (ctypes.c_void_p * len(_SYMBOLS))(
                *[ctypes.cast(dart_lib[sym], ctypes.c_void_p).value for sym in _SYMBOLS.values()])
        except (OSError, AttributeError) as exc:  # a dartpy without these exported symbols
            raise NativeUnavailable(f"dartpy does not export the DART symbols the C step needs: {exc}") from exc
        # PyDLL: the calls keep the GIL, as dartpy's world.step() does (no two DART worlds step at once on
        # threads of one process, as before)
        lib = ctypes.PyDLL(str(compile_source(SOURCE, "cpgsim_dart", origin="robots/dart/c/dart_loop.c")))
        declare(lib, PROTOTYPES)
        _LIB, _FNS = lib, fns
    return _LIB, _FNS  # type: ignore[return-value]


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
