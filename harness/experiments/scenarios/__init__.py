"""The built-in robot scenarios as TOML files (their schema: :mod:`harness.experiments.scenario`)."""
