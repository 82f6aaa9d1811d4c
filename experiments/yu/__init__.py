"""Yu 2019 experiments: robot scenarios (flat, step, ditches, prototype) and the paper's figures."""
