"""Parameter study of the walking gait: period and max |lambda| of the closed loop against one scenario key.

Each value is a full :func:`~cpgsim.experiments.gait_verify.verify_gait` (the key set with
``--set`` semantics, e.g. ``controller.fsm.T_g``), run one after the other in this process (a batch:
the machine's cores are the co-simulation's; each value costs about as much as ``cpgsim verify gait``).
A value whose gait cannot be verified (the robot falls, the section is never crossed) is a row with
its ``error`` and no numbers.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from cpgsim.experiments.gait_verify import verify_gait
from cpgsim.verify.gait import GaitOptions
from cpgsim.verify.stride import SectionError


def study(scenario: str, sets: Mapping[str, Any] | None, key: str, values: Sequence[Any],
          options: GaitOptions | None = None, joints: bool = False, warmup: float | None = None,
          progress: Callable[[str], None] | None = None) -> list[dict[str, Any]]:
    """One row per value: ``value``, ``period_s``, ``max_abs_multiplier``, ``stable``, ``fd_agreement``,
    ``perturbation`` (predicted, measured), or ``error``."""
    rows = []
    for value in values:
        if progress:
            progress(f"study {key} = {value}")
        try:
            run = verify_gait(scenario, {**(sets or {}), key: value}, options, joints=joints, warmup=warmup,
                              progress=progress)
        except SectionError as exc:
            rows.append({"value": value, "error": str(exc)})
            continue
        r = run.result
        rows.append({"value": value, "period_s": r.period,
                     "max_abs_multiplier": float(np.max(np.abs(r.multipliers))), "stable": r.stable,
                     "status": r.status()[0],
                     "fd_agreement": r.fd_agreement,
                     "perturbation": {"predicted": r.perturbation["predicted"],
                                      "measured": r.perturbation["measured"]},
                     "wall_time_s": run.wall_s})
    return rows


def plot_study(rows: Sequence[Mapping[str, Any]], key: str, path: Path) -> Path:
    """max |lambda| (with the unit line) and the period against the value."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ok = [r for r in rows if "error" not in r]
    x = [float(r["value"]) for r in ok]
    fig, ax = plt.subplots(1, 2, figsize=(10, 4))
    ax[0].plot(x, [r["max_abs_multiplier"] for r in ok], "o-", label="max |lambda| (FD Jacobian)")
    ax[0].plot(x, [r["perturbation"]["measured"] or np.nan for r in ok], "s--", mfc="none",
               label="measured decay per stride")
    ax[0].axhline(1.0, color="k", lw=0.8)
    ax[0].set_xlabel(key)
    ax[0].set_ylabel("multiplier modulus")
    ax[0].set_ylim(0, max(1.1, *[r["max_abs_multiplier"] * 1.1 for r in ok]) if ok else 1.1)
    ax[0].legend(fontsize=8)
    ax[0].set_title("gait stability")
    ax[1].plot(x, [r["period_s"] for r in ok], "o-")
    ax[1].set_xlabel(key)
    ax[1].set_ylabel("gait period (s)")
    ax[1].set_title("gait period")
    for r in rows:
        if "error" in r:
            ax[0].axvline(float(r["value"]), color="r", lw=0.8, ls=":")
    fig.tight_layout()
    from cpgsim.experiments.gait_report import save_png

    return save_png(fig, path)
