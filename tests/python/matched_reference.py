"""Pole-zero matched discretisation of normalised Butterworth low-passes by python-control.

Reads a JSON list of {"order", "cutoff_hz", "sample_period"} on stdin and prints, for each,
python-control's `sample_system(G, T, method='matched')` as JSON: the denominator
[1, a1, ..., aN] and the numerator's coefficients (python-control keeps every zero at infinity
as a delay, so the numerator is a single constant K: G(z) = K / A(z) = K z^-N / A(z^-1)).
The analogue Butterworth is built from its poles on the unit circle (scipy.signal.buttap),
scaled to the cut-off; its DC gain is 1.
"""
import json
import sys

import control
import numpy as np
from scipy import signal


def matched(order, cutoff_hz, sample_period):
    _, poles, gain = signal.buttap(order)
    wc = 2.0 * np.pi * cutoff_hz
    den = np.real(np.poly(poles * wc))
    analogue = control.tf([np.real(gain) * wc**order], den)
    digital = control.sample_system(analogue, sample_period, method="matched")
    num = np.real(np.atleast_1d(np.squeeze(digital.num[0][0])))
    den = np.real(np.atleast_1d(np.squeeze(digital.den[0][0])))
    scale = den[0]
    return {"numerator": list(num / scale), "denominator": list(den / scale)}


def main():
    cases = json.load(sys.stdin)
    out = [dict(case, **matched(case["order"], case["cutoff_hz"], case["sample_period"])) for case in cases]
    json.dump(out, sys.stdout)


if __name__ == "__main__":
    main()
