"""A minimal C host for FMI 2.0 Co-Simulation FMUs (``templates/fmi2_host.c``), used by the tests and the
benchmark to run FMUs without Python (and without fmpy's per-step Python overhead)."""

from __future__ import annotations

import os
import subprocess
import tempfile
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cpgsim.fmus.export.build import TEMPLATES, compiler, fmi_headers
from cpgsim.fmus.export.model_description import ExportError


def build_host(directory: str | Path | None = None) -> Path:
    """Compile the host program (into ``directory``, default a cache folder) and return its path."""
    out_dir = Path(directory) if directory else Path(tempfile.gettempdir()) / "cpgsim-fmi2-host"
    out_dir.mkdir(parents=True, exist_ok=True)
    exe = out_dir / "fmi2_host"
    src = TEMPLATES / "fmi2_host.c"
    if exe.exists() and exe.stat().st_mtime >= src.stat().st_mtime:
        return exe
    include = fmi_headers(2)[0].parent
    tmp = out_dir / f"fmi2_host.{os.getpid()}.tmp"
    proc = subprocess.run([compiler(), "-O2", "-std=c99", f"-I{include}", str(src), "-o", str(tmp), "-ldl"],
                          capture_output=True, text=True)
    if proc.returncode != 0:
        raise ExportError(f"compiling the FMI host failed: {proc.stderr.strip()[:1000]}")
    os.replace(tmp, exe)
    return exe


@dataclass
class HostRun:
    time: np.ndarray | None
    values: np.ndarray | None
    elapsed: float
    stderr: str


def extract_fmu(fmu: str | Path, directory: str | Path) -> Path:
    directory = Path(directory)
    with zipfile.ZipFile(fmu) as zf:
        zf.extractall(directory)
    return directory


def run_host(exe: Path, library: Path, guid: str, steps: int, dt: float, outputs: list[int],
             sets: dict[int, float] | None = None, record: bool = False, resources: Path | None = None,
             preload: str | None = None, env: dict[str, str] | None = None, timeout: float = 600) -> HostRun:
    """Run ``steps`` steps of ``dt`` in the C host (a subprocess with environment ``env``)."""
    uri = (resources.resolve().as_uri() + "/") if resources else "file:///nonexistent/"
    cmd = [str(exe), str(library), guid, uri, str(steps), repr(float(dt))]
    if outputs:
        cmd += ["-o", ",".join(str(v) for v in outputs)]
    for vr, value in (sets or {}).items():
        cmd += ["-s", f"{vr}={value!r}"]
    if record:
        cmd.append("-r")
    if preload:
        cmd += ["-p", preload]
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env if env is not None else {}, timeout=timeout)
    if proc.returncode != 0:
        raise RuntimeError(f"FMI host failed (exit {proc.returncode}): {proc.stderr.strip()[-2000:]}")
    lines = proc.stdout.strip().splitlines()
    elapsed = float(lines[-1].split("=", 1)[1])
    if record:
        data = np.array([[float(v) for v in ln.split(",")] for ln in lines[:-1]])
        return HostRun(data[:, 0], data[:, 1:], elapsed, proc.stderr)
    return HostRun(None, None, elapsed, proc.stderr)
