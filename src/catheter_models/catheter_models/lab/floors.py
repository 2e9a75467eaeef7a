"""The floors a model's error is judged against: the sensor's noise and a black box.

A model is *adequate* only when its held-out error is near the sensor's noise; the black box
says whether what is left above the noise is learnable from the pressure at all. Both
floors are measured on the data at hand:

* **The noise floor**: the angle sensor's white noise, estimated from the measured bend
  itself. The bend of a catheter is smooth at the sensor's rate (its fastest dynamics,
  a ringing tip at a few hertz, are slow against 250 Hz), so the second difference of the
  measurement is noise almost everywhere; its median absolute value, robust to the few fast
  moves, gives the noise's standard deviation (``Var(Δ²e) = 6 σ²`` for white noise). No model
  can beat it on held-out data.
* **The black-box floor**: what a flexible learner without physical names reaches on the
  same training data, scored on the same held-out data. :class:`FilterBankReference` is a
  bank of generic linear dynamics (first-order lags from 4 ms to 20 s, damped resonances
  from 1 to 20 Hz, short delays) over a play-operator expansion of the pressure (the
  ``free_pi`` core's plays) and a time ramp, fitted by ridge regression: it can learn lags,
  delays, creep, ringing, drift and sensor filters without being told which. If it does much
  better than the model, the rest of the error is learnable, and the model misses physics.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Final

import numpy as np
import numpy.typing as npt
from scipy import signal as sps

from catheter_models.models.base import Recording
from catheter_models.models.cores import FreePI, one_blas_thread
from catheter_models.units import pa_to_bar, rad_to_deg

FloatArray = npt.NDArray[np.float64]

_MAD_TO_STD: Final = 1.4826
"""Median absolute deviation to standard deviation, for Gaussian noise."""


def noise_std_deg(recordings: Sequence[Recording]) -> float:
    """The angle sensor's white-noise standard deviation [deg], estimated from the data.

    The median absolute second difference, robust to fast motion, over all recordings.
    """
    parts = [np.diff(rad_to_deg(r.angle_rad), 2) for r in recordings if r.angle_rad.size > 3]
    if not parts:
        return float("nan")
    d2 = np.concatenate(parts)
    mad = float(np.median(np.abs(d2 - np.median(d2))))
    return _MAD_TO_STD * mad / math.sqrt(6.0)


LAG_TIME_CONSTANTS_S: Final = (0.004, 0.012, 0.035, 0.1, 0.3, 1.0, 3.0, 10.0)
RESONANCES_HZ: Final = (1.5, 3.0, 5.0, 8.0, 13.0)
DELAYS_S: Final = (0.02, 0.05)
REFERENCE_COLUMNS: Final = 24
"""Play combinations the bank works on (the strongest of the pressure's play expansion)."""


@dataclass
class FilterBankReference:
    """The black-box reference: generic linear dynamics over hysteresis features.

    ``y = sum_k sum_f w_kf F_f[φ_k] + c t``: ``φ_k`` are the strongest combinations of the
    pressure's plays (the ``free_pi`` expansion), ``F_f`` a bank of lags, resonances and
    delays (and the identity), ``t`` the time since the recording began. Linear in ``w``:
    identified by ridge regression in seconds.
    """

    ridge: float = 1e-5
    rate_hz_: float = 0.0
    basis_: FloatArray | None = None
    weights_: FloatArray | None = None
    beta_s_: float = 0.0

    def _features(self, x_bar: FloatArray) -> FloatArray:
        assert self.basis_ is not None
        phi = self._plays.design(x_bar, self.rate_hz_, self.beta_s_) @ self.basis_
        rate = self.rate_hz_
        cols = [phi]
        for tau in LAG_TIME_CONSTANTS_S:
            a = math.exp(-1.0 / (rate * tau))
            cols.append(sps.lfilter([1.0 - a], [1.0, -a], phi, axis=0, zi=a * phi[:1])[0])
        for f_hz in RESONANCES_HZ:
            w0, zeta = 2.0 * math.pi * f_hz, 0.1
            b, a = sps.bilinear([w0 * w0], [1.0, 2.0 * zeta * w0, w0 * w0], fs=rate)
            zi = sps.lfilter_zi(b, a)[:, None] * phi[:1]
            cols.append(sps.lfilter(b, a, phi, axis=0, zi=zi)[0])
        for delay in DELAYS_S:
            n = round(delay * rate)
            cols.append(np.vstack([np.repeat(phi[:1], n, axis=0), phi[:-n]]))
        t = np.arange(x_bar.size)[:, None] / rate
        return np.hstack([*cols, t])

    @one_blas_thread
    def fit(self, train: Sequence[Recording]) -> FilterBankReference:
        """Identify on ``train`` (all at one sample rate)."""
        self.rate_hz_ = train[0].rate_hz
        self._plays = FreePI()
        xs = [pa_to_bar(r.pressure_pa) for r in train]
        ys = [rad_to_deg(r.angle_rad) for r in train]
        self._plays.fit(xs, ys, self.rate_hz_)
        self.beta_s_ = self._plays.beta_s or 0.0
        gram = sum(
            a.T @ a / a.shape[0]
            for a in (self._plays.design(x, self.rate_hz_, self.beta_s_) for x in xs)
        )
        _, vectors = np.linalg.eigh(np.asarray(gram))
        assert self._plays.weights is not None
        q, _ = np.linalg.qr(
            np.hstack([self._plays.weights[:, None], vectors[:, ::-1][:, :REFERENCE_COLUMNS]])
        )
        self.basis_ = q
        solver = FreePI(ridge=self.ridge)
        self.weights_, _ = solver.solve([self._features(x) for x in xs], ys)
        return self

    def predict_deg(self, x_bar: FloatArray) -> FloatArray:
        """Bend [deg] for pressure [bar], from rest."""
        assert self.weights_ is not None
        out: FloatArray = self._features(x_bar) @ self.weights_
        return out

    def rmse_deg(self, recordings: Sequence[Recording]) -> float:
        """Pooled held-out RMSE [deg]."""
        err = np.concatenate(
            [
                self.predict_deg(pa_to_bar(r.pressure_pa)) - rad_to_deg(r.angle_rad)
                for r in recordings
            ]
        )
        return float(np.sqrt(np.mean(err**2)))
