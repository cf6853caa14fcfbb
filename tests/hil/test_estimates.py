"""The judgement of the RLS mass on the bus (hil/estimates.py): an estimate following its
forgetting's exponential window passes, one biased off it (the guide's friction left in the
load cell) does not, and where the window outlasts the segment its error at the end is judged."""

import numpy as np

from hil.estimates import LoadEstimates, follows_forgetting, settling

PERIOD_S, MEMORY_S = 0.002, 1.0


def _estimates(true_kg, start_kg, span_s, bias_kg=0.0, tau_s=MEMORY_S):
    cycles = np.arange(0, int(span_s / PERIOD_S), 48)           # CTRL_LOAD's every 48th SYNC
    t = cycles * PERIOD_S
    mass = true_kg + bias_kg + (start_kg - true_kg - bias_kg) * np.exp(-t / tau_s)
    return LoadEstimates(cycles, mass, np.zeros(len(cycles)), np.zeros(len(cycles)))


def test_an_estimate_on_its_forgetting_window_settles_in_time():
    est = _estimates(4.35, 1.35, 3.14)
    g = settling(est, 0, 10**6, 4.35, PERIOD_S, MEMORY_S)
    assert g["predicted_s"] == np.round(MEMORY_S * np.log(3.0 / 0.435), 3)
    assert abs(g["settled_s"] - g["predicted_s"]) < 0.1 and follows_forgetting(g, 1.2)


def test_a_biased_or_slower_estimate_fails():
    biased = settling(_estimates(4.35, 1.35, 3.14, bias_kg=1.1), 0, 10**6, 4.35, PERIOD_S, MEMORY_S)
    slow = settling(_estimates(4.35, 1.35, 3.14, tau_s=1.5), 0, 10**6, 4.35, PERIOD_S, MEMORY_S)
    assert biased["settled_s"] is None and not follows_forgetting(biased, 1.2)
    assert not follows_forgetting(slow, 1.2)


def test_a_segment_shorter_than_the_window_is_judged_by_its_last_error():
    est = _estimates(1.35, 7.35, 3.14)
    g = settling(est, 0, 10**6, 1.35, PERIOD_S, MEMORY_S)
    assert g["predicted_s"] > g["span_s"] and g["settled_s"] is None
    assert follows_forgetting(g, 1.2)
    lagging = settling(_estimates(1.35, 7.35, 3.14, tau_s=1.4), 0, 10**6, 1.35, PERIOD_S, MEMORY_S)
    assert not follows_forgetting(lagging, 1.2)
