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

from cpgsim.harness.native import NativeUnavailable, compile_source

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

SOURCE = r"""
#include <stddef.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

typedef struct { double *data; ptrdiff_t rows; } vecxd;  /* Eigen::VectorXd's storage */
typedef void (*world_step_t)(void *, _Bool);
typedef double (*world_time_step_t)(const void *);
typedef const void *(*world_result_t)(const void *);
typedef size_t (*num_contacts_t)(const void *);
typedef const char *(*get_contact_t)(const void *, size_t);
typedef void (*set_forces_t)(void *, const vecxd *);
typedef double (*get_dof_t)(const void *, size_t);
typedef size_t (*num_dofs_t)(const void *);
typedef int (*feval_t)(void *);

enum { LINK = 10, BODY = 100, OTHER = 1000, MAX_OBJECTS = 256 };
enum { FORCE = 48, OBJECT1 = 72, OBJECT2 = 80 };  /* offsets in dart::collision::Contact */

typedef struct {
    world_step_t world_step; world_time_step_t world_time_step; world_result_t world_result;
    num_contacts_t num_contacts; get_contact_t get_contact; set_forces_t set_forces;
    get_dof_t get_position, get_velocity; num_dofs_t num_dofs;
} dart_api;

typedef struct {
    dart_api api;
    void *world, *skel;
    vecxd forces;            /* the plant's servo forces (one per dof) */
    double *force_world;     /* 18: per-leg contact force sums (world frame) */
    unsigned char *link;     /* 6 booleans (numpy bool) */
    double *pos, *vel;       /* the dofs' positions and velocities after the step */
    double *contact;         /* 1: the body contact flag as the readout's input */
    size_t ndofs;
    feval_t readout; void *readout_ctx;   /* the compiled readout, or NULL */
    size_t nobj; const void *obj[MAX_OBJECTS]; int code[MAX_OBJECTS];
    double step_seconds; long step_count;  /* time inside World::step (benchmarks) */
    double ctrl_seconds, loop_seconds;     /* time in the controller step of cpgsim_dart_loop, in the loop */
} plant_ctx;

static double seconds_since(const struct timespec *t0) {
    struct timespec t1;
    clock_gettime(CLOCK_MONOTONIC, &t1);
    return (double)(t1.tv_sec - t0->tv_sec) + 1e-9 * (double)(t1.tv_nsec - t0->tv_nsec);
}

static int code_of(const plant_ctx *c, const void *obj) {
    for (size_t i = 0; i < c->nobj; i++) if (c->obj[i] == obj) return c->code[i];
    return -1;
}

/* the Python readout's loop: 0 ok (no body contact), 2 ok with body contact, 1 an unknown object */
static int read_contacts(plant_ctx *c, double *f, unsigned char *link) {
    const void *res = c->api.world_result(c->world);
    size_t n = c->api.num_contacts(res);
    int body = 0;
    for (int k = 0; k < 18; k++) f[k] = 0.0;
    for (int k = 0; k < 6; k++) link[k] = 0;
    for (size_t i = 0; i < n; i++) {
        const char *ct = c->api.get_contact(res, i);
        int code = code_of(c, *(void *const *)(ct + OBJECT2));
        double sign = -1.0;
        if (code < 0) return 1;
        if (code == OTHER) {
            code = code_of(c, *(void *const *)(ct + OBJECT1));
            if (code < 0) return 1;
            if (code == OTHER) continue;
            sign = 1.0;
        }
        if (code < LINK) {
            const double *force = (const double *)(ct + FORCE);
            f[3 * code] += sign * force[0];
            f[3 * code + 1] += sign * force[1];
            f[3 * code + 2] += sign * force[2];
        } else if (code == BODY) {
            body = 1;
        } else {
            link[code - LINK] = 1;
        }
    }
    return body ? 2 : 0;
}

void *cpgsim_dart_bind(void **fns, void *world, void *skel, double *forces, double *force_world,
                       unsigned char *link, double *pos, double *vel, double *contact, size_t ndofs,
                       void *readout, void *readout_ctx) {
    plant_ctx *c = calloc(1, sizeof(plant_ctx));
    if (!c) return NULL;
    memcpy(&c->api, fns, sizeof(dart_api));
    c->world = world; c->skel = skel;
    c->forces.data = forces; c->forces.rows = (ptrdiff_t)ndofs;
    c->force_world = force_world; c->link = link; c->pos = pos; c->vel = vel; c->contact = contact;
    c->ndofs = ndofs; c->readout = (feval_t)readout; c->readout_ctx = readout_ctx;
    return c;
}

void cpgsim_dart_unbind(void *c) { free(c); }

int cpgsim_dart_register(void *vc, const void *obj, int code) {
    plant_ctx *c = vc;
    if (code_of(c, obj) >= 0) return 0;
    if (c->nobj >= MAX_OBJECTS) return -1;
    c->obj[c->nobj] = obj; c->code[c->nobj] = code; c->nobj++;
    return 0;
}

double cpgsim_dart_time_step(void *vc) { plant_ctx *c = vc; return c->api.world_time_step(c->world); }
size_t cpgsim_dart_num_dofs(void *vc) { plant_ctx *c = vc; return c->api.num_dofs(c->skel); }

/* the dofs' positions and velocities into pos/vel, the body flag into contact, then the readout */
int cpgsim_dart_outputs(void *vc, int body) {
    plant_ctx *c = vc;
    for (size_t i = 0; i < c->ndofs; i++) {
        c->pos[i] = c->api.get_position(c->skel, i);
        c->vel[i] = c->api.get_velocity(c->skel, i);
    }
    c->contact[0] = body ? 1.0 : 0.0;
    return c->readout ? c->readout(c->readout_ctx) : 0;
}

/* one world step with the servo forces held, the contacts summed, the outputs read. Returns 0 / 2 (body
   contact), 1 when a contact has a collision object not registered yet (outputs not read: the caller
   reads that step's contacts itself), -1 when the readout failed. */
int cpgsim_dart_step(void *vc) {
    plant_ctx *c = vc;
    struct timespec t0;
    c->api.set_forces(c->skel, &c->forces);  /* world.step() clears them */
    clock_gettime(CLOCK_MONOTONIC, &t0);
    c->api.world_step(c->world, 1);
    c->step_seconds += seconds_since(&t0);
    c->step_count++;
    int rc = read_contacts(c, c->force_world, c->link);
    if (rc == 1) return 1;
    if (cpgsim_dart_outputs(c, rc == 2)) return -1;
    return rc;
}

typedef int (*commit_t)(void *, double, int, int);
static int dart_loop(plant_ctx *c, void *step_commit, void *sctx, int nx, int nz, double *u, const double *y,
                     int nmap, const long long *u_idx, const long long *o_idx, const double *O, int nO,
                     const long long *qt_idx, double *qt, int *changed, int *updated, double kp, int npick,
                     const long long *yi, double *Yrec, double *Orec, int k0, int k1, const double *times,
                     int *status);

/* The closed loop of a compiled controller step and this plant for macro steps k0 .. k1-1 (one world step
   each), as the co-simulation master and the plant's Python do them (Jacobi, no feedthrough): u <- plant
   outputs O; controller step at times[k] with commit; record row k (Yrec: y[yi], Orec: O); q_target <-
   y[qt] (a new target: forces[6 + i] = kp q_target[i], as DartHexapod._update_servo_forces); world step,
   contact sums, outputs (the readout writes O). Returns the rows recorded and sets *status: 0 done, 1 the
   controller state went non-finite at the last row (plant not stepped), 2 the controller step failed (row
   not recorded) or the readout failed, 4 a target not finite at the last row (plant not stepped: the
   caller hands it to the plant's Python), 5 the last row's world step met an unregistered collision object
   (contacts and outputs not read: the caller reads them). *changed: the plant's "target changed" flag;
   *updated counts the steps that took a new target. */
int cpgsim_dart_loop(void *vc, void *step_commit, void *sctx, int nx, int nz, double *u, const double *y,
                     int nmap, const long long *u_idx, const long long *o_idx, const double *O, int nO,
                     const long long *qt_idx, double *qt, int *changed, int *updated, double kp, int npick,
                     const long long *yi, double *Yrec, double *Orec, int k0, int k1, const double *times,
                     int *status) {
    plant_ctx *c = vc;
    struct timespec l0;
    clock_gettime(CLOCK_MONOTONIC, &l0);
    int rows = dart_loop(c, step_commit, sctx, nx, nz, u, y, nmap, u_idx, o_idx, O, nO, qt_idx, qt, changed, updated,
                         kp, npick, yi, Yrec, Orec, k0, k1, times, status);
    c->loop_seconds += seconds_since(&l0);
    return rows;
}

static int dart_loop(plant_ctx *c, void *step_commit, void *sctx, int nx, int nz, double *u, const double *y,
                     int nmap, const long long *u_idx, const long long *o_idx, const double *O, int nO,
                     const long long *qt_idx, double *qt, int *changed, int *updated, double kp, int npick,
                     const long long *yi, double *Yrec, double *Orec, int k0, int k1, const double *times,
                     int *status) {
    commit_t commit = (commit_t)step_commit;
    double q[18];
    for (int k = k0; k < k1; ++k) {
        double *yr = Yrec + (long)(k - k0) * npick, *orow = Orec + (long)(k - k0) * nO;
        for (int i = 0; i < nmap; ++i) u[u_idx[i]] = O[o_idx[i]];
        struct timespec t0;
        clock_gettime(CLOCK_MONOTONIC, &t0);
        int rc = commit(sctx, times[k], nx, nz);
        c->ctrl_seconds += seconds_since(&t0);
        if (rc == 2) { *status = 2; return k - k0; }
        for (int i = 0; i < npick; ++i) yr[i] = y[yi[i]];
        for (int i = 0; i < nO; ++i) orow[i] = O[i];
        if (rc == 1) { *status = 1; return k - k0 + 1; }
        int finite = 1;
        for (int i = 0; i < 18; ++i) {  /* what the plant's numpy sum might call not finite goes to Python */
            q[i] = y[qt_idx[i]];
            finite &= q[i] - q[i] == 0.0 && q[i] < 1e306 && q[i] > -1e306;
        }
        if (!finite) { *status = 4; return k - k0 + 1; }
        if (*changed || memcmp(q, qt, sizeof q)) {
            memcpy(qt, q, sizeof q);
            for (int i = 0; i < 18; ++i) c->forces.data[6 + i] = qt[i] * kp;
            ++*updated;
        }
        *changed = 0;
        rc = cpgsim_dart_step(c);
        if (rc == 1) { *status = 5; return k - k0 + 1; }
        if (rc < 0) { *status = 2; return k - k0 + 1; }
    }
    *status = 0;
    return k1 - k0;
}

double cpgsim_dart_step_seconds(void *vc) { return ((plant_ctx *)vc)->step_seconds; }
long cpgsim_dart_step_count(void *vc) { return ((plant_ctx *)vc)->step_count; }
double cpgsim_dart_ctrl_seconds(void *vc) { return ((plant_ctx *)vc)->ctrl_seconds; }
double cpgsim_dart_loop_seconds(void *vc) { return ((plant_ctx *)vc)->loop_seconds; }
"""


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
        lib = ctypes.PyDLL(str(compile_source(SOURCE, "cpgsim_dart")))
        vp, dp = ctypes.c_void_p, ctypes.POINTER(ctypes.c_double)
        lib.cpgsim_dart_bind.argtypes = [vp, vp, vp, dp, dp, vp, dp, dp, dp, ctypes.c_size_t, vp, vp]
        lib.cpgsim_dart_bind.restype = vp
        lib.cpgsim_dart_unbind.argtypes = [vp]
        lib.cpgsim_dart_register.argtypes = [vp, vp, ctypes.c_int]
        lib.cpgsim_dart_time_step.argtypes = [vp]
        lib.cpgsim_dart_time_step.restype = ctypes.c_double
        lib.cpgsim_dart_num_dofs.argtypes = [vp]
        lib.cpgsim_dart_num_dofs.restype = ctypes.c_size_t
        lib.cpgsim_dart_outputs.argtypes = [vp, ctypes.c_int]
        lib.cpgsim_dart_step.argtypes = [vp]
        ip, lp = ctypes.POINTER(ctypes.c_int), ctypes.POINTER(ctypes.c_longlong)
        lib.cpgsim_dart_loop.argtypes = [vp, vp, vp, ctypes.c_int, ctypes.c_int, dp, dp, ctypes.c_int, lp, lp, dp,
                                         ctypes.c_int, lp, dp, ip, ip, ctypes.c_double, ctypes.c_int, lp, dp, dp,
                                         ctypes.c_int, ctypes.c_int, dp, ip]
        lib.cpgsim_dart_step_seconds.argtypes = [vp]
        lib.cpgsim_dart_step_seconds.restype = ctypes.c_double
        lib.cpgsim_dart_step_count.argtypes = [vp]
        lib.cpgsim_dart_step_count.restype = ctypes.c_long
        lib.cpgsim_dart_ctrl_seconds.argtypes = [vp]
        lib.cpgsim_dart_ctrl_seconds.restype = ctypes.c_double
        lib.cpgsim_dart_loop_seconds.argtypes = [vp]
        lib.cpgsim_dart_loop_seconds.restype = ctypes.c_double
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
