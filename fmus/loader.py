"""Any FMI file to a runnable graph: an ``.fmu`` as one block, an ``.ssp`` as its system."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from cpgsim.fmus.importer.block import fmu_graph
from cpgsim.fmus.ssp import import_ssp


def load_fmu_graph(spec: str | Path) -> Any:
    """What ``cpgsim simulate FILE`` runs for an ``.fmu`` (:func:`cpgsim.fmus.importer.block.fmu_graph`) or ``.ssp``
    (:func:`cpgsim.fmus.ssp.import_ssp`) file."""
    path = Path(spec)
    if path.suffix.lower() == ".ssp":
        return import_ssp(path)
    return fmu_graph(path)
