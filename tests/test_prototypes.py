"""Issue 56: each library's ctypes prototype table checked against its C by the C compiler itself.

:func:`cpgsim.harness.c.toolchain.check_prototypes` compiles (``-fsyntax-only``) the library's C followed by one
call per function of the table with arguments of the table's ctypes types, conversions refused: a table
whose argument count, kind, width, pointee or order, or return type differs from the C does not compile.
A planted mismatch of each kind is refused, so the check is not vacuous.
"""

from __future__ import annotations

import ctypes

import casadi as ca
import pytest

from cpgsim.harness import native
from cpgsim.harness.c import toolchain

pytestmark = pytest.mark.skipif(toolchain.compiler() is None, reason="needs a C compiler")


def step_source() -> str:
    """CasADi's C of a small step with the model step's calling convention (``cpgsim_step_impl``)."""
    t, x, z, u, p = (ca.SX.sym(n, k) for n, k in (("t", 1), ("x", 2), ("z", 1), ("u", 1), ("p", 1)))
    fn = ca.Function("cpgsim_step_impl", [t, x, z, u, p], [x + t * u, z * p, ca.vertcat(x, z)])
    return native.casadi_c_source([fn], "proto_step")


def function_source() -> str:
    a = ca.SX.sym("a", 2)
    return native.casadi_c_source([ca.Function("cpgsim_fn_impl", [a], [a * 2])], "proto_fn")


def libraries() -> dict[str, tuple[str, toolchain.Prototypes, tuple[str, ...]]]:
    """Name -> (the C as compiled, its prototype table, extra compiler flags)."""
    return {
        "horizon": (step_source() + native.DRIVER, native.PROTOTYPES, ()),
        "function": (function_source() + native.FUNCTION_DRIVER, native.FUNCTION_PROTOTYPES, ()),
    }


@pytest.mark.parametrize("name", sorted(libraries()))
def test_each_prototype_table_matches_its_c(name):
    source, table, flags = libraries()[name]
    assert toolchain.check_prototypes(source, table, flags, origin=name) is None


def _planted(table: toolchain.Prototypes, name: str, restype=..., argtypes=None) -> toolchain.Prototypes:
    old_res, old_args = table[name]
    return {**table, name: (old_res if restype is ... else restype, old_args if argtypes is None else argtypes)}


_dbl, _int, _ll, _vp = ctypes.c_double, ctypes.c_int, ctypes.c_longlong, ctypes.c_void_p
_dp = ctypes.POINTER(ctypes.c_double)
_HORIZON = native.PROTOTYPES["cpgsim_horizon"][1]
PLANTED = {
    "one argument fewer": ("cpgsim_step_commit", ..., [_vp, _dbl, _int]),
    "one argument more": ("cpgsim_step1", ..., [_vp, _dbl, _int]),
    "int for double": ("cpgsim_step1", ..., [_vp, _int]),
    "double for int": ("cpgsim_step_commit", ..., [_vp, _dbl, _dbl, _int]),
    "long long for int": ("cpgsim_worker_run", ..., [_vp, _dbl, _ll]),
    "int for long": ("cpgsim_worker_start", ..., [_vp, _int, _int, _int]),
    "pointer to another type": ("cpgsim_horizon", ..., [*_HORIZON[:10], ctypes.POINTER(_int), *_HORIZON[11:]]),
    "two arguments swapped": ("cpgsim_horizon", ..., [_HORIZON[0], _HORIZON[3], *_HORIZON[1:3], *_HORIZON[4:]]),
    "pointer for a number": ("cpgsim_step1", ..., [_vp, _dp]),
    "double returned, int in C": ("cpgsim_step1", _dbl, None),
    "int returned, void in C": ("cpgsim_unbind", _int, None),
}


@pytest.mark.parametrize("case", sorted(PLANTED))
def test_a_planted_mismatch_does_not_compile(case):
    fn, restype, argtypes = PLANTED[case]
    source, table, flags = libraries()["horizon"]
    error = toolchain.check_prototypes(source, _planted(table, fn, restype, argtypes), flags, origin="horizon")
    assert error is not None and error.startswith("horizon: ") and "\n" not in error, case


def test_the_batch_table_matches_its_c():
    from cpgsim.harness import batch
    assert toolchain.check_prototypes(step_source() + batch.BATCH_DRIVER, batch.PROTOTYPES, origin="batch") is None


def test_the_batch_job_struct_has_the_c_layout():
    """Each field of ctypes' ``_Job`` at the ``offsetof`` the compiler gives ``cpgsim_batch_job``, same size."""
    from cpgsim.harness import batch
    fields = [name for name, _ in batch._Job._fields_]
    got = toolchain.struct_offsets(step_source() + batch.BATCH_DRIVER, batch._Job._c_name_, fields)
    want = {name: getattr(batch._Job, name).offset for name in fields} | {"<size>": ctypes.sizeof(batch._Job)}
    assert got == want


def test_a_struct_offset_mismatch_shows():
    """The layout check is not vacuous: a struct with a field of another width moves the offsets after it."""
    class Planted(ctypes.Structure):
        _fields_ = [("a", ctypes.c_int), ("b", ctypes.c_int)]
    got = toolchain.struct_offsets("typedef struct { long long a; int b; } planted;", "planted", ["a", "b"])
    assert got != {"a": Planted.a.offset, "b": Planted.b.offset, "<size>": ctypes.sizeof(Planted)}
    assert got == {"a": 0, "b": 8, "<size>": 16}


def test_the_mujoco_table_matches_its_c():
    mj = pytest.importorskip("cpgsim.robots.mujoco.native")
    include, _ = mj.mujoco_paths()
    assert toolchain.check_prototypes(mj.SOURCE, mj.PROTOTYPES, (f"-I{include}",), origin="mujoco") is None


def test_the_dart_table_matches_its_c():
    dn = pytest.importorskip("cpgsim.robots.dart.native")
    assert toolchain.check_prototypes(dn.library_source(), dn.PROTOTYPES, origin="dart") is None
