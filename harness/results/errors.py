"""The error of the results files."""

from __future__ import annotations


class ResultsError(ValueError):
    """A results file is missing, malformed, or a column does not exist."""
