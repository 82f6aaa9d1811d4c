"""A robot run's summary as returned to Python: the ``summary.json`` dictionary, shown in a notebook as a
table of what happened (verdict with each failed criterion's value and limit, distance, falls, reflexes)."""

from __future__ import annotations

import html
import math
from typing import Any

SHOWN = ("scenario", "t_end", "complete", "success", "distance_m", "speed_m_s", "fell", "fell_reason",
         "max_tilt_deg", "stalled", "waiting_share", "real_time_factor")


def _fmt(value: Any) -> str:
    if isinstance(value, float):
        return f"{value:.4g}" if math.isfinite(value) else str(value)
    return str(value)


def _criterion_row(name: str, c: Any) -> str:
    value, limit = (c.get("value"), c.get("limit", "")) if isinstance(c, dict) else (c, "")
    cells = (str(name), _fmt(value), _fmt(limit))
    return "<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in cells) + "</tr>"


class RunSummary(dict):
    """``summary.json`` as a dictionary (every key of the file), with a notebook view."""

    def _repr_html_(self) -> str:
        verdict = "success" if self.get("success") else "FAILED: " + ", ".join(self.get("criteria_failed", []))
        rows = "".join(f"<tr><th>{html.escape(k)}</th><td>{html.escape(_fmt(self[k]))}</td></tr>"
                       for k in SHOWN if k in self)
        criteria = self.get("criteria", {})
        crit_rows = "".join(_criterion_row(name, c) for name, c in criteria.items()) \
            if isinstance(criteria, dict) else ""
        crit = (f"<table><tr><th>criterion</th><th>value</th><th>limit</th></tr>{crit_rows}</table>"
                if crit_rows else "")
        events = "".join(f"<li>{html.escape(str(e.get('kind')))} on {html.escape(str(e.get('leg')))} at "
                         f"{e.get('t', float('nan')):.3f} s</li>" for e in self.get("reflexes", [])[:20])
        return (f"<div><b>{html.escape(str(self.get('scenario', 'run')))}: {html.escape(verdict)}</b>"
                f"<table>{rows}</table>{crit}<p>reflex events:</p><ul>{events or '<li>none</li>'}</ul></div>")
