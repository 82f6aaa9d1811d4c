"""Yu et al. 2019 (hexapod CPG controller): linear converter, sensory neurons, elevator and searching
reflexes, gait FSM, and the leg and six-leg controller graphs built from them."""
