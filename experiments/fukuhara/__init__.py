"""Fukuhara 2022 experiments: gaits by speed, amputation and the gap-crossing trials."""
