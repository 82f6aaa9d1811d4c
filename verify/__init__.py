"""Limit-cycle verification: periodic orbits by shooting, Floquet multipliers, synchronisation, reports."""
