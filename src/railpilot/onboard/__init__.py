"""The onboard intelligent driving system (paper 001, sections 2.3-2.5): no I/O."""
