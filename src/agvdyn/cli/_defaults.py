"""Defaults and choices of CLI options that are library constants, written as literals.

Declaring the typer options must import nothing heavy (``agvdyn --help`` answers in well under 0.5 s), so
the option declarations take these instead of importing the library modules that own the constants;
``tests/test_startup.py`` checks that each equals the library's.
"""
from __future__ import annotations

#: agvdyn.identifiability.QR_TOLERANCE
QR_TOLERANCE = 1e-6
#: agvdyn.io.STOP_TOLERANCE (steering angles beyond the stops that are clipped, rad)
STOP_TOLERANCE = 0.01
#: agvdyn.kinematics.MODE_TOLERANCE (mode detection, rad)
MODE_TOLERANCE = 0.02
#: agvdyn.identification.IdentificationSettings().uncertainty
UNCERTAINTY = "jackknife"
#: the names of agvdyn.identification.estimators.ESTIMATORS, in its order
ESTIMATORS = ("ols", "wls", "robust", "bounded")
