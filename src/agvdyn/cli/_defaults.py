"""Defaults and choices of CLI options that are library constants, written as literals.

Declaring the typer options must import nothing heavy (``agvdyn --help`` answers in well under 0.5 s), so
the option declarations take these instead of importing the library modules that own the constants;
``tests/test_startup.py`` and ``tests/test_settings_layout.py`` check that each equals the library's.
"""
from __future__ import annotations

#: agvdyn.identifiability.QR_TOLERANCE
QR_TOLERANCE = 1e-6
#: agvdyn.io.STOP_TOLERANCE (steering angles beyond the stops that are clipped, rad)
STOP_TOLERANCE = 0.01
#: agvdyn.kinematics.MODE_TOLERANCE (mode detection, rad)
MODE_TOLERANCE = 0.02
#: agvdyn.identification.IdentificationSettings().uncertainty.method
UNCERTAINTY = "jackknife"
#: the names of agvdyn.identification.estimators.ESTIMATORS, in its order
ESTIMATORS = ("ols", "wls", "robust", "bounded")

# Defaults of the identification options of ``identify``, ``validate`` and ``report``: each is the default of
# the IdentificationSettings field OPTION_FIELDS names (tests/test_settings_layout.py checks every one, and
# that every option of the three commands defaults to it).
#: rows.filtering
FILTERING = "parallel"
#: rows.filter.cutoff (rad/s)
CUTOFF = 40.0
#: rows.filter.order
ORDER = 4
#: rows.stiction_threshold (m/s, rad/s)
STICTION = 0.05
#: rows.steering_threshold (rad/s)
STEERING_STICTION = 0.1
#: rows.stiction_guard (multiples of 1 / cutoff)
STICTION_GUARD = 2.0
#: rows.steering_guard (multiples of 1 / cutoff)
STEERING_GUARD = 4.0
#: fit.torque_offsets
OFFSETS = True
#: fit.max_inflation
MAX_INFLATION = 100.0
#: fit.max_relative_std
MAX_RELATIVE_STD = 0.5
#: fit.estimator
ESTIMATOR = "wls"

#: Each identification option of the CLI (its parameter name) and the IdentificationSettings field it sets.
OPTION_FIELDS = {
    "filtering": "rows.filtering", "cutoff": "rows.filter.cutoff", "order": "rows.filter.order",
    "stiction": "rows.stiction_threshold", "steering_stiction": "rows.steering_threshold",
    "stiction_guard": "rows.stiction_guard", "steering_guard": "rows.steering_guard", "segments": "rows.segments",
    "slip_threshold": "rows.slip_threshold", "torque_lead": "rows.torque_lead", "offsets": "fit.torque_offsets",
    "max_inflation": "fit.max_inflation", "max_relative_std": "fit.max_relative_std", "estimator": "fit.estimator",
    "unexcited": "fit.unexcited", "uncertainty": "uncertainty.method", "bandwidth": "uncertainty.bandwidth",
}

# The model options of ``identify`` (issue 30; tests/test_model_selection.py checks them against agvdyn.model_spec).
#: agvdyn.model_spec.DELAY_RANGE (s)
DELAY_RANGE = (0.0, 0.02)
#: agvdyn.model_spec.STRIBECK_RANGE (rad/s)
STRIBECK_RANGE = (0.005, 0.5)
