"""Native FMU vs PythonFMU: the same VDP network (Yu Y5, Table 1), 10 s at 1 ms, FMI 2 Co-Simulation.

(a) ``cpgsim.fmus.export.exporter.export_fmu``: CasADi-generated C + the FMI layer, no Python at run time;
(b) a PythonFMU (``pythonfmu``) whose slave calls the *same* compiled step (and post-update) CasADi
    functions, serialized into the FMU's resources, through zero-copy CasADi buffers.

Each FMU is stepped (i) by fmpy (``simulate_fmu``, every step recorded) and (ii) by the minimal C host
``fmus/templates/fmi2_host.c``, compiled here, which calls ``fmi2DoStep`` and reads the six outputs with
``fmi2GetReal`` after every step (fmpy's own Python loop costs microseconds per step and hides the
difference). The host runs the PythonFMU with libpython preloaded and ``PYTHONHOME`` set. Both FMUs'
outputs are checked against each other before timing.

Run: ``python benchmarks/bench_fmu.py [--repeat 5] [--seconds 10] [--json out.json]``.
Targets: native >= 100x faster in the C host, and faster in fmpy too.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import sysconfig
import tempfile
import time
from pathlib import Path

import numpy as np

from cpgsim.components.networks import leader_follower_network  # noqa: E402
from cpgsim.fmus.export.build import model_functions  # noqa: E402
from cpgsim.fmus.export.exporter import export_fmu  # noqa: E402
from cpgsim.fmus.export.host import build_host, extract_fmu, run_host  # noqa: E402
from cpgsim.harness.compile import compile_graph  # noqa: E402

SLAVE = '''"""The VDP network stepped from Python by its compiled CasADi step function (cpgsim benchmark)."""
import json
import os

import casadi as ca
import numpy as np
from pythonfmu import Fmi2Causality, Fmi2Initial, Fmi2Slave, Fmi2Variability, Real


class PyNetwork(Fmi2Slave):
    author = "cpgsim"
    description = "Yu Y5 network: the compiled step called from Python"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        with open(os.path.join(self.resources, "meta.json")) as f:
            meta = json.load(f)
        self.dt = meta["dt"]
        self.k = 0
        self.t_arr = np.zeros(1)
        self.x, self.z = np.array(meta["x0"]), np.array(meta["z0"])
        self.u, self.p = np.array(meta["u0"]), np.array(meta["p0"])
        self.xn, self.zn = np.zeros_like(self.x), np.zeros_like(self.z)
        self.xp, self.zp, self.y = np.zeros_like(self.x), np.zeros_like(self.z), np.zeros(meta["ny"])
        self.valid = False
        self._fns = []
        self.step_eval = self._buffer("step.casadi", (self.t_arr, self.x, self.z, self.u, self.p),
                                      (self.xn, self.zn, None))
        self.post_eval = self._buffer("post.casadi", (self.t_arr, self.x, self.z, self.u, self.p),
                                      (self.xp, self.zp, self.y))
        for name, j, start in meta["outputs"]:
            self.register_variable(Real(name, causality=Fmi2Causality.output, variability=Fmi2Variability.continuous,
                                        initial=Fmi2Initial.exact, start=start, getter=lambda j=j: self._out(j)))

    def _buffer(self, fname, args, results):
        fn = ca.Function.load(os.path.join(self.resources, fname))
        self._fns.append(fn)
        buf, evaluate = fn.buffer()
        for i, a in enumerate(args):
            buf.set_arg(i, memoryview(a))
        for i, r in enumerate(results):
            if r is not None:
                buf.set_res(i, memoryview(r))
        self._fns.append(buf)
        return evaluate

    def _out(self, j):
        if not self.valid:
            self.t_arr[0] = self.k * self.dt
            self.post_eval()
            self.valid = True
        return float(self.y[j])

    def do_step(self, current_time, step_size):
        for _ in range(int(round(step_size / self.dt))):
            self.t_arr[0] = self.k * self.dt
            self.step_eval()
            self.x[:] = self.xn
            self.z[:] = self.zn
            self.k += 1
        self.valid = False
        return True
'''


def build_python_fmu(directory: Path, dt: float) -> Path:
    """The PythonFMU of the network: slave script + serialized CasADi functions as resources."""
    from pythonfmu.builder import FmuBuilder

    model = compile_graph(leader_follower_network(), dt)
    fns = {f.name().split("_", 1)[1]: f for f in model_functions(model, "net")}
    res = directory / "pyres"
    res.mkdir(exist_ok=True)
    fns["step"].save(str(res / "step.casadi"))
    fns["post"].save(str(res / "post.casadi"))
    y0 = np.asarray(fns["post"](0.0, model.x0, model.z0, np.zeros(model.inputs.size), model.p0)[2]).ravel()
    outputs = [(name, model.signals_layout.index(src).start, float(y0[model.signals_layout.index(src).start]))
               for name, src in model.graph_outputs.items()]
    meta = {"dt": dt, "x0": model.x0.tolist(), "z0": model.z0.tolist(), "u0": [0.0] * model.inputs.size,
            "p0": model.p0.tolist(), "ny": model.signals_layout.size, "outputs": outputs}
    (res / "meta.json").write_text(json.dumps(meta))
    script = directory / "pynetwork.py"
    script.write_text(SLAVE)
    return FmuBuilder.build_FMU(script, dest=directory / "PyNetwork.fmu",
                                project_files=[res / "step.casadi", res / "post.casadi", res / "meta.json"])


def python_env() -> tuple[str, dict[str, str]]:
    """libpython to preload and the environment the PythonFMU needs inside the C host."""
    libdir = sysconfig.get_config_var("LIBDIR")
    lib = str(Path(libdir) / sysconfig.get_config_var("LDLIBRARY"))
    env = {"PYTHONHOME": sys.base_prefix, "PATH": os.environ.get("PATH", "/usr/bin:/bin")}
    site = sysconfig.get_paths()["purelib"]
    env["PYTHONPATH"] = site
    return lib, env


def _fmpy_time(path: Path, seconds: float, dt: float) -> tuple[float, np.ndarray]:
    import fmpy

    t0 = time.perf_counter()
    res = fmpy.simulate_fmu(str(path), fmi_type="CoSimulation", stop_time=seconds, step_size=dt, output_interval=dt)
    return time.perf_counter() - t0, res


def bench(seconds: float = 10.0, dt: float = 1e-3, repeat: int = 5) -> dict:
    from fmpy import read_model_description

    n = int(round(seconds / dt))
    with tempfile.TemporaryDirectory(prefix="cpgsim-bench-fmu-") as tmp:
        tmp = Path(tmp)
        t0 = time.perf_counter()
        native = export_fmu(leader_follower_network(), tmp / "network.fmu", fmi=2, kind="cs", dt=dt).path
        t_export = time.perf_counter() - t0
        t0 = time.perf_counter()
        pyfmu = build_python_fmu(tmp, dt)
        t_pybuild = time.perf_counter() - t0
        exe = build_host(tmp / "host")
        lib, env = python_env()
        runs: dict[str, list[float]] = {k: [] for k in ("fmpy_native", "fmpy_python", "host_native", "host_python")}
        cases = {}
        for key, path in (("native", native), ("python", pyfmu)):
            md = read_model_description(str(path))
            d = extract_fmu(path, tmp / f"x_{key}")
            outs = [v for v in md.modelVariables if v.causality == "output"]
            libpath = d / "binaries" / "linux64" / f"{md.coSimulation.modelIdentifier}.so"
            cases[key] = (md, d, outs, libpath)
        # same values from both FMUs, both hosts
        recorded = {}
        for key, (md, d, outs, libpath) in cases.items():
            r = run_host(exe, libpath, md.guid, n, dt, [v.valueReference for v in outs], record=True,
                         resources=d / "resources", preload=lib if key == "python" else None,
                         env=env if key == "python" else {})
            recorded[key] = r.values
        agree_host = float(np.max(np.abs(recorded["native"] - recorded["python"])))
        for _ in range(repeat):  # interleaved, so that machine load hits all alike
            for key, (md, d, outs, libpath) in cases.items():
                r = run_host(exe, libpath, md.guid, n, dt, [v.valueReference for v in outs],
                             resources=d / "resources", preload=lib if key == "python" else None,
                             env=env if key == "python" else {})
                runs[f"host_{key}"].append(r.elapsed)
                elapsed, res = _fmpy_time(native if key == "native" else pyfmu, seconds, dt)
                runs[f"fmpy_{key}"].append(elapsed)
                recorded[f"fmpy_{key}"] = res
        names = [v.name for v in cases["native"][2]]
        agree_fmpy = max(float(np.max(np.abs(recorded["fmpy_native"][c] - recorded["fmpy_python"][c]))) for c in names)
    med = {k: statistics.median(v) for k, v in runs.items()}
    return {
        "steps": n, "dt": dt, "repeat": repeat, "export_s": t_export, "pythonfmu_build_s": t_pybuild,
        "median_s": med, "per_step_us": {k: v / n * 1e6 for k, v in med.items()},
        "ratio_host": med["host_python"] / med["host_native"],
        "ratio_fmpy": med["fmpy_python"] / med["fmpy_native"],
        "max_diff_native_vs_python_host": agree_host, "max_diff_native_vs_python_fmpy": agree_fmpy,
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--dt", type=float, default=1e-3)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--json", help="also write the numbers to this JSON file")
    args = ap.parse_args(argv)
    out = bench(args.seconds, args.dt, args.repeat)
    med, per = out["median_s"], out["per_step_us"]
    print(f"VDP network, {out['steps']} steps of {out['dt']} s, median of {out['repeat']}")
    print(f"{'runner':28s} {'median':>12s} {'per step':>12s}")
    for key, label in (("host_native", "C host, native FMU"), ("host_python", "C host, PythonFMU"),
                       ("fmpy_native", "fmpy, native FMU"), ("fmpy_python", "fmpy, PythonFMU")):
        print(f"{label:28s} {med[key] * 1e3:10.2f} ms {per[key]:9.3f} us")
    print(f"native speed-up: C host {out['ratio_host']:.0f}x (target >= 100x), fmpy {out['ratio_fmpy']:.1f}x "
          f"(target > 1x)")
    print(f"export {out['export_s'] * 1e3:.0f} ms, PythonFMU build {out['pythonfmu_build_s'] * 1e3:.0f} ms; "
          f"max |native - python| {out['max_diff_native_vs_python_host']:.1e} (host), "
          f"{out['max_diff_native_vs_python_fmpy']:.1e} (fmpy)")
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
