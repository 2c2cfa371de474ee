"""Experiments on the simulated world: the demo and the reproduction of the paper's figures."""
