"""Symbolic layer: scenario files, follower models and the CasADi closed loop."""
