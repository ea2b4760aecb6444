"""Identification of the dynamic parameters from logs: stacked regression of eq. (22)-(25).

Row pipeline (paper sec. 6-7), one module per stage, data flowing one way::

    stretches   each continuous recording filtered and differentiated once; odometry (eq. 3),
                slip speed of the redundant rolling constraints, entries of Theta (eq. 16)
    rows        mode of every row from its configuration (labels are hints), slip, stiction,
                edges -> rows H_k^T Theta p = H_k^T B u of eq. (19)   (equations, slip)
    regression  stacked system (eq. 22), known parameters to the right (eq. 24), rank and
                quality checks, column-scaled least squares (eq. 25)
    plausibility  negative masses, inertias, frictions refused with the likely sign mistake
    result      :class:`Identification`

The entry points are :func:`identify` (vehicle logs, loaded by :func:`agvdyn.io.load_logs` or
opened by :func:`agvdyn.io.open_logs`) and :func:`identify_lifted` (the lifted-wheel test);
:func:`experiment_of` tells which one a set of logs needs.
"""
from agvdyn.identification.equations import EquationBlock, equation_block, generalized_velocity
from agvdyn.identification.fit import fit_blocks, fit_regression
from agvdyn.identification.lifted import LiftedWheelIdentification, experiment_of, identify_lifted
from agvdyn.identification.pipeline import identify, load_logs, platform_for, row_passes
from agvdyn.identification.plausibility import ImplausibleError, SignConventionError
from agvdyn.identification.regression import (
    Dependency,
    Estimator,
    LeastSquares,
    UnidentifiableError,
    dependent_parameters,
    stacked_system,
    variance_inflation,
)
from agvdyn.identification.result import Identification
from agvdyn.identification.rows import LogRows, RowCounts, log_equations, log_rows, row_modes
from agvdyn.identification.settings import (
    CHASSIS_COORDINATES,
    DEFAULT_FIXED,
    EXCITATION,
    OFFSET_NAMES,
    STEERING_COORDINATES,
    EstimatorName,
    Filtering,
    FitSettings,
    IdentificationSettings,
    RobustLoss,
    RowSettings,
    UncertaintyMethod,
    UncertaintySettings,
    Unexcited,
)
from agvdyn.identification.slip import SlipEvent

__all__ = [
    "DEFAULT_FIXED", "EXCITATION", "OFFSET_NAMES", "STEERING_COORDINATES", "CHASSIS_COORDINATES",
    "Filtering", "IdentificationSettings", "RowSettings", "FitSettings", "UncertaintySettings", "EstimatorName",
    "RobustLoss", "Unexcited", "UncertaintyMethod", "EquationBlock", "UnidentifiableError", "ImplausibleError", "SignConventionError",
    "Dependency", "Estimator", "LeastSquares", "Identification", "SlipEvent", "RowCounts", "LogRows",
    "equation_block", "generalized_velocity", "log_equations", "log_rows", "row_modes", "stacked_system",
    "dependent_parameters", "variance_inflation", "identify", "fit_blocks", "fit_regression", "load_logs", "platform_for",
    "row_passes", "identify_lifted", "experiment_of", "LiftedWheelIdentification",
]

#: Entry points of the model beyond the paper (issue 30), imported when first used (start-up of the CLI).
_MODEL_SELECTION = {"identify_model": "model_search", "compare_models": "selection", "ModelSelection": "selection"}
__all__ += list(_MODEL_SELECTION)


def __getattr__(name: str):
    if name in _MODEL_SELECTION:
        import importlib

        return getattr(importlib.import_module(f"agvdyn.identification.{_MODEL_SELECTION[name]}"), name)
    raise AttributeError(f"module 'agvdyn.identification' has no attribute {name!r}")
