"""The built-in robot scenarios as TOML files (their schema: :mod:`cpgsim.experiments.scenario`)."""
