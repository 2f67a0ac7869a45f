"""railpilot: train braking control and train-ground dispatch communication.

Subpackages
-----------
units       every unit conversion; SI inside the core
vehicle     train and line models (papers 000, 002, 003)
brakes      brake actuators: EP blending, lag + delay
control     controllers behind one small interface; they never see the plant
sim         reference curves, disturbances, the stepping engine, metrics, batches
scenario    TOML scenario files -> validated, typed configuration
report      figures and the HTML report (the only place that imports matplotlib)
reproduce   one module per paper result that ``railpilot reproduce`` can rebuild
link        train-ground protocol core (paper 001), no I/O
net         asyncio TCP adapters around the link core
"""

__version__ = "0.1.0"
