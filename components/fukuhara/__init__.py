"""Fukuhara et al. 2022 (load-sensing limb controller): limb-mode switching by rules 1-4, the foot
trajectory of its Appendix A, and the six-leg controller graph."""
