"""The DART plant's C step and the controller + DART loop in C (robots/dart_native.py, robots/dart_fused.py):
the same numbers as the plant's Python loop and the Python master, bit for bit."""

from __future__ import annotations

import re

import numpy as np
import pytest

from cpgsim.robots.dart.plant import DartHexapod


def _walk(robot: DartHexapod, steps: int) -> np.ndarray:
    """Moving targets large enough to bang shanks and links on the ground; every output of every step."""
    robot.setup(0.0)
    rows = []
    for k in range(steps):
        q = robot.q0 + 0.5 * np.sin(2 * np.pi * k / 400.0 + np.arange(18))
        robot.set_inputs({"q_target": q})
        robot.do_step(robot.time, 1e-3)
        rows.append(np.concatenate([v.ravel() for v in robot.get_outputs().values()]))
    return np.array(rows)


@pytest.mark.slow
@pytest.mark.parametrize("settle", [0.0, 0.1])
def test_c_step_equals_python_step(settle):
    slow = DartHexapod(settle=settle, native=False)
    a = _walk(slow, 1500)
    assert slow.native_step is None
    fast = DartHexapod(settle=settle)  # the settling steps in C too
    b = _walk(fast, 1500)
    if fast.native_step is None:
        pytest.skip("no C step here (no C compiler or a dartpy without DART's symbols)")
    assert fast.native_step.checks_left == 0  # compared with the Python readout, then on its own
    seconds, steps, _ = fast.native_step.step_time()
    assert steps == 1500 + round(settle * 1000) and seconds > 0
    np.testing.assert_array_equal(a, b)
    assert np.abs(a[:, :18]).max() > 0  # something moved
    assert fast.link_contacts().dtype == bool and slow.link_contacts().tolist() == fast.link_contacts().tolist()
    assert fast.body_contact() == slow.body_contact()
    snap_a, snap_b = slow.snapshot(), fast.snapshot()
    for field in ("t", "positions", "velocities", "q_target", "forces", "force_world", "link_contact", "n_steps"):
        np.testing.assert_array_equal(getattr(snap_a, field), getattr(snap_b, field))


def test_a_readout_that_differs_switches_back_to_python(monkeypatch):
    robot = DartHexapod()
    robot.setup(0.0)
    if robot.native_step is None:
        pytest.skip("no C step here")
    python_readout = robot.read_contacts

    def skewed() -> None:  # the Python readout sees another force than the C step
        python_readout()
        robot._force_world[2] += 1.0
    monkeypatch.setattr(robot, "read_contacts", skewed)
    with pytest.warns(RuntimeWarning, match="stays in Python"):
        for _ in range(5):
            robot.set_inputs({"q_target": robot.q0})
            robot.do_step(robot.time, 1e-3)
    assert robot.native_step is None
    robot.set_inputs({"q_target": robot.q0})
    robot.do_step(robot.time, 1e-3)  # the Python loop goes on
    assert robot.time == pytest.approx(0.006)


def test_native_step_off_by_argument_and_by_scenario_key(monkeypatch):
    """``native=False`` keeps the Python step; the environment variable that once decided is not read."""
    from cpgsim.experiments.runner import build_scenario

    monkeypatch.setenv("CPGSIM_DART_NATIVE", "1")
    robot = DartHexapod(native=False)
    robot.setup(0.0)
    assert robot.native_step is None
    robot.terminate()
    setup = build_scenario("flat", {"robot.native": False})
    assert setup.graph.blocks[setup.robot].native is False
    monkeypatch.setenv("CPGSIM_DART_NATIVE", "0")
    robot = DartHexapod()
    robot.setup(0.0)
    stepped_in_c = robot.native_step is not None
    robot.terminate()
    if not stepped_in_c:
        pytest.skip("no C step here (no C compiler or a dartpy without DART's symbols)")



def test_fused_loop_hands_a_target_that_is_not_finite_to_the_plant():
    """A controller step that sends NaN targets: the C loop stops before stepping DART with them and the
    plant's ``set_inputs`` refuses them, as under the Python master."""
    import ctypes

    from cpgsim.components.core import ModelError
    from cpgsim.harness.cosim.contracts import FusedRequest

    robot = DartHexapod()
    robot.setup(0.0)
    if robot.native_step is None:
        pytest.skip("no C step here")
    y, u, q0 = np.zeros(18), np.zeros(3), robot.q0.copy()
    calls: list[float] = []

    @ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.c_double, ctypes.c_int, ctypes.c_int)
    def commit(ctx, t, nx, nz):  # a stand-in for the compiled controller step: y <- targets
        calls.append(t)
        y[:] = np.nan if len(calls) == 60 else q0
        return 0

    request = FusedRequest(ctypes.cast(commit, ctypes.c_void_p).value, 0, 0, 0, u, y,
                           [(slice(0, 3), "body_position")], {"q_target": slice(0, 18)}, np.arange(3), 1e-3)
    loop = robot.fused_loop(request)
    assert loop is not None
    times = np.arange(201) * 1e-3
    with pytest.raises(ModelError, match="not finite"):
        loop.run(0, 100, times)
    assert len(calls) == 60 and robot.time == pytest.approx(0.059)
    body = robot.output_slices["body_position"]
    np.testing.assert_array_equal(u, loop.O[59, body])  # the controller's input: the plant's body position
    robot.terminate()


def test_unverified_dartpy_keeps_the_python_loop(monkeypatch):
    """Another dartpy release: no C step (its object layouts were not checked), a warning, the same numbers."""
    from cpgsim.robots.dart import native as dart_native

    monkeypatch.setattr(dart_native.dart, "__version__", "6.99.0", raising=False)
    monkeypatch.setattr(dart_native, "_LIB", None)
    monkeypatch.setattr(dart_native, "_FAILED", None)
    with pytest.raises(dart_native.NativeUnavailable, match=r"dartpy 6\.99\.0: the C step was verified on"):
        dart_native._library()
    robot = DartHexapod()
    with pytest.warns(RuntimeWarning, match="DART's step stays in Python"):
        robot.setup(0.0)
    assert robot.native_step is None


def _fresh_load(monkeypatch) -> None:
    """Forget this process's loaded (or refused) C step, so the next plant loads and checks it again."""
    from cpgsim.robots.dart import native as dart_native

    for name in ("_LIB", "_FNS", "_FAILED"):
        monkeypatch.setattr(dart_native, name, None)


def test_the_installed_dartpy_passes_the_load_check(monkeypatch):
    """Every symbol of the table is exported, and the self-test's contacts read by the C at the table's
    offsets are dartpy's ``getContacts()``, bit for bit."""
    from cpgsim.robots.dart import native as dart_native

    _fresh_load(monkeypatch)
    try:
        lib, fns = dart_native._library()
    except dart_native.NativeUnavailable as exc:
        if "C compiler" in str(exc):
            pytest.skip(str(exc))
        raise
    assert dart_native._self_test(lib, fns) is None
    assert all(fns[i] for i in range(len(dart_native._SYMBOLS)))


@pytest.mark.parametrize("table, key, wrong, message", [
    ("_SYMBOLS", "get_contact", "_ZNK4dart9collision15CollisionResult10getContactEj",
     r"does not export the DART symbols the C step needs: "
     r"get_contact \(_ZNK4dart9collision15CollisionResult10getContactEj\)"),
    ("LAYOUT", "contact_force", 24, r"Contact\.force at offset 24 reads \[.*\] where getContacts\(\) says"),
    ("LAYOUT", "contact_object2", 72, r"Contact\.collisionObject2 at offset 72 reads 0x"),
])
def test_a_dartpy_that_does_not_match_the_table_keeps_the_python_loop(monkeypatch, table, key, wrong, message):
    """A symbol dartpy does not export, or an offset that is not DART's: one line naming dartpy's version and
    what did not match, no C step, and the run is the Python loop's, number for number."""
    from cpgsim.robots.dart import native as dart_native

    expected = _walk(DartHexapod(native=False), 200)
    _fresh_load(monkeypatch)
    monkeypatch.setitem(getattr(dart_native, table), key, wrong)
    robot = DartHexapod()
    with pytest.warns(RuntimeWarning) as caught:
        got = _walk(robot, 200)
    lines = [str(w.message) for w in caught if "stays in Python" in str(w.message)]
    assert len(lines) == 1 and "\n" not in lines[0], lines
    version = dart_native.dart.__version__
    assert re.search(rf"^{robot.name}: DART's step stays in Python \(dartpy {re.escape(version)}\b.*{message}",
                     lines[0]), lines
    assert robot.native_step is None
    np.testing.assert_array_equal(got, expected)
