"""User-facing CLI error (its own module so ``python -m harness.cli`` and imports share one class)."""

from __future__ import annotations


class CliError(Exception):
    """A user-facing error: printed as one line, exit status ``code`` (2 = bad input)."""

    def __init__(self, message: str, code: int = 2) -> None:
        super().__init__(message)
        self.code = code
