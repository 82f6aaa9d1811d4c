"""Benchmark suites (controllers x terrains x seeds) for ``cpgsim bench`` (:mod:`cpgsim.experiments.bench`)."""
