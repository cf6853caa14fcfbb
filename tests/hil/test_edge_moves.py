"""`hydrapod design edge-moves`: random single moves sent at the capacity check's own edge
(the time scale its refusal names), in process, emulator truth. What the check accepts there
completes without fault within 10 mm (a move or two; the 70-move figure is docs/MEASUREMENTS.md's).
Its bad arguments: tests/project/test_cli_error_paths.py."""

import json
import math

import numpy as np
import pytest

from hil.cli import main
from hil.design.edge_moves import edge_moves, random_move


def test_the_moves_stay_in_the_workspace_and_are_repeatable():
    first, again = (random_move(np.random.default_rng(5)) for _ in range(2))
    assert first == again
    rng = np.random.default_rng(5)
    for _ in range(200):
        payload, supply, start, target, segment, accel = random_move(rng)
        assert 0.56 <= target[2] <= 0.76 and max(abs(target[0]), abs(target[1])) <= 0.12
        assert segment >= 2.2 * accel


@pytest.mark.slow                       # in process, a few seconds of emulated rig
def test_a_move_at_the_checks_edge_completes_within_10_mm(capsys):
    assert main(["design", "edge-moves", "--moves", "1", "--seed", "3", "--workers", "1", "--json"]) == 0
    runs = json.loads(capsys.readouterr().out)
    assert runs and all(r["fault"] == "NONE" for r in runs)
    assert all(r["max_error_mm"] < 10.0 for r in runs)


@pytest.mark.slow                       # in process, a few seconds of emulated rig
def test_a_refused_move_is_sent_at_the_named_scale_and_slower():
    runs = edge_moves(1, seed=8, workers=1, factors=(1.0, 1.2))
    assert [r.factor for r in runs] == [1.0, 1.2]                   # refused as sent: at the edge, then slower
    assert math.isclose(runs[1].time_scale / runs[0].time_scale, 1.2, rel_tol=1e-9)
    assert all(r.fault == "NONE" and r.max_error_mm < 10.0 for r in runs)

