"""Brake actuators: shoe friction, lag + delay, EP blending."""
