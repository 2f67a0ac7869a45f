"""The ``[montecarlo]`` table's typed form: see :mod:`railpilot.sim.sweep`.

Kept under this name for scenario files' readers; the definitions live in sim/ so that the
simulator never imports the scenario package (scenario -> sim, never back).
"""

from railpilot.sim.sweep import VARIABLE_PARAMETERS, Distribution, MonteCarloSpec

__all__ = ["VARIABLE_PARAMETERS", "Distribution", "MonteCarloSpec"]
