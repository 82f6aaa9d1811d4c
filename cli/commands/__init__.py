"""Subcommands of the ``cpgsim`` CLI, discovered automatically (one module each)."""
