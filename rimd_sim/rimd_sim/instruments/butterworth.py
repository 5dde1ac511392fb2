"""The instruments' Butterworth sections without ``scipy.signal``, whose import would slow every node's start.

A node's start waits for its imports, and importing ``scipy.signal`` is a large share of the simulator node's
start (docs/benchmarks.md, "Latency"), only for the two filters of the instrument chain (:mod:`.sensors`): a
2nd-order low-pass and a 1st-order high-pass. Both are designed here as ``scipy.signal.butter(N, cutoff, btype, fs=fs,
output="sos")`` designs them, step by step with the same numpy operations in the same order (the analog
prototype's poles, the frequency pre-warped for the bilinear transform, the transform, and the pairing of poles
and zeros into one section), so that the coefficients are the same floating-point numbers, signs of zeros
included, and the readings bit-identical: ``tests/instruments/test_butterworth.py`` compares them with scipy's over
the whole range of cutoffs.
"""

from __future__ import annotations

import numpy as np

__all__ = ["highpass1_sos", "lowpass2_sos"]


def _warped(cutoff: float, fs: float) -> float:
    """The analog cutoff (rad/s at a sample rate of 2) that the bilinear transform maps onto ``cutoff`` Hz."""
    wn = np.asarray(cutoff, dtype=np.float64) / (float(fs) / 2)
    if not 0.0 < wn < 1.0:
        raise ValueError(f"cutoff {cutoff!r} Hz must be between 0 and half the sample rate {fs!r} Hz")
    return float(2 * 2.0 * np.tan(np.pi * wn / 2.0))


def _section(zeros: list[float], poles: list[complex] | list[float], gain: float) -> np.ndarray:
    """One second-order section ``[b0, b1, b2, a0, a1, a2]`` (shape (1, 6)) from its zeros, poles and gain."""
    b = np.ones(1)
    for zero in zeros:
        b = np.convolve(b, np.array([1.0, -zero]), mode="full")
    a = np.ones(1, dtype=np.result_type(*poles))
    one = np.ones_like(np.asarray(poles)[0])
    for pole in poles:
        a = np.convolve(a, np.stack((one, -pole)), mode="full")
    if np.iscomplexobj(a):   # the poles are a conjugate pair: the polynomial is real
        a = np.real(a).copy()
    sos = np.zeros(6)
    sos[3 - len(b):3] = np.multiply(np.asarray(1.0), b)
    sos[6 - len(a):6] = a
    sos[:3] *= gain
    return sos[None, :]


def lowpass2_sos(cutoff: float, fs: float) -> np.ndarray:
    """``scipy.signal.butter(2, cutoff, btype="lowpass", fs=fs, output="sos")``: one section, shape (1, 6).

    Raises:
        ValueError: ``cutoff`` is not between 0 and ``fs / 2``.
    """
    wo = _warped(cutoff, fs)
    m = np.arange(-1, 2, 2, dtype=np.float64)
    poles = wo * -np.exp(1j * np.pi * m / (2 * 2))   # the analog prototype's, scaled to the cutoff
    gain = 1.0 * wo ** 2
    poles_z = (4.0 + poles) / (4.0 - poles)           # bilinear transform (sample rate 2); the zeros: -1, -1
    gain_z = gain * np.real(np.prod(4.0 - np.zeros(0)) / np.prod(4.0 - poles))
    upper = poles_z[poles_z.imag > 0][0]
    return _section([-1.0, -1.0], [upper, np.conj(upper)], gain_z)


def highpass1_sos(cutoff: float, fs: float) -> np.ndarray:
    """``scipy.signal.butter(1, cutoff, btype="highpass", fs=fs, output="sos")``: one section, shape (1, 6).

    Raises:
        ValueError: ``cutoff`` is not between 0 and ``fs / 2``.
    """
    wo = _warped(cutoff, fs)
    prototype = -np.exp(1j * np.pi * np.zeros(1) / 2)
    poles = wo / prototype                               # low-pass to high-pass: one zero at 0
    zeros = np.zeros(1)
    gain = 1.0 * np.real(np.prod(-np.zeros(0)) / np.prod(-prototype))
    zeros_z = (4.0 + zeros) / (4.0 - zeros)             # bilinear transform (sample rate 2)
    poles_z = (4.0 + poles) / (4.0 - poles)
    gain_z = gain * np.real(np.prod(4.0 - zeros) / np.prod(4.0 - poles))
    pole = float(poles_z.real[0])
    # The odd order is padded with a pole and a zero at 0; the pole is paired with the nearer zero first.
    zero = float(zeros_z[0])
    pair = [zero, 0.0] if abs(zero - pole) <= abs(0.0 - pole) else [0.0, zero]
    return _section(pair, [pole, 0.0], gain_z)
