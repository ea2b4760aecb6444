"""Closed-loop vehicle simulation (see agvdyn.simulation.simulate)."""
