"""mpcdrive: safe autonomous driving with Model Predictive Control.

Layers (imports point one way): units/types -> models, paths, scene -> ocp -> solvers
-> control -> sim -> scenarios -> cli.  SI units and radians everywhere inside the library.
"""

__version__ = "0.1.0"
