"""The thesis's result tables, as printed (real rig, thesis ch. 8 and 11): RMSE/MAE [deg], NRMSE.

MAE is the *maximum* absolute error (eq. 5.13). Keys are our preset names for the same
signals (``catheter_models.signals``).
"""

from __future__ import annotations

from typing import Final, NamedTuple


class Row(NamedTuple):
    """One model on one signal: RMSE [deg], maximum absolute error [deg], NRMSE [fraction]."""

    rmse_deg: float
    mae_deg: float
    nrmse: float


MODELLING: Final[dict[str, dict[str, Row]]] = {
    # Table 8.1: descending sine differing from the training data.
    "model_test_descending_sine": {
        "drdpi": Row(1.404, 6.226, 0.0454),
        "svr": Row(0.758, 1.833, 0.0245),
        "lstm": Row(0.363, 1.227, 0.0117),
    },
    # Table 8.2: attenuated down-chirp with shifted baseline.
    "model_test_down_chirp": {
        "drdpi": Row(1.220, 2.830, 0.0628),
        "svr": Row(0.797, 3.535, 0.0410),
        "lstm": Row(0.816, 2.271, 0.0420),
    },
    # Table 8.3: ascending up-chirp with zero baseline.
    "model_test_up_chirp": {
        "drdpi": Row(1.066, 4.284, 0.0499),
        "svr": Row(0.760, 1.687, 0.0356),
        "lstm": Row(0.500, 1.924, 0.0234),
    },
    # Table 8.4: arbitrarily varying signal with plateaus.
    "model_test_arbitrary_plateaus": {
        "drdpi": Row(1.479, 2.979, 0.0607),
        "svr": Row(0.920, 2.010, 0.0378),
        "lstm": Row(0.588, 1.932, 0.0242),
    },
}

CONTROL: Final[dict[str, dict[str, Row]]] = {
    # Table 11.1: descending sinusoidal trajectory.
    "traj_descending_sine": {"idrdpi": Row(1.67, 4.37, 0.0904), "clstm": Row(0.32, 1.45, 0.0173)},
    # Table 11.2: attenuated down-chirp trajectory with shifted baseline.
    "traj_down_chirp": {"idrdpi": Row(2.46, 4.84, 0.1262), "clstm": Row(0.56, 1.54, 0.0287)},
    # Table 11.3: ascending up-chirp trajectory with zero baseline.
    "traj_up_chirp": {"idrdpi": Row(1.85, 4.41, 0.1059), "clstm": Row(0.29, 1.53, 0.0164)},
    # Table 11.4: arbitrarily varying trajectory with small variations.
    "traj_arbitrary_small_variations": {
        "idrdpi": Row(3.97, 8.52, 0.1474),
        "clstm": Row(0.47, 2.44, 0.0173),
    },
}

TRAINING_TIME_S: Final[dict[str, float]] = {
    "drdpi": 3.5 * 3600,  # MATLAB GA, Intel i7 CPU (sec. 5.3.2)
    "svr": 20 * 60,  # sec. 6.3, CPU
    "lstm": 10 * 60,  # sec. 7.3, 4 GB GPU
    "idrdpi": 3.5 * 3600,  # sec. 9.2, GA on CPU (plus the GPI identifications)
    "clstm": 2.25 * 3600,  # sec. 10.3.1, 4 GB GPU
}
