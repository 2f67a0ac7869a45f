"""Trains, ground and link together in simulated time (docs/cosim.md)."""
