"""Benchmark suites (controllers x terrains x seeds) for ``cpgsim bench`` (:mod:`harness.experiments.bench`)."""
