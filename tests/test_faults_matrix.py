"""The fault-injection matrix's short form (every case on the hexapod, emulator and
controller as processes on the bus) passes: each fault detected within its bound, held,
and after RESET + ENABLE a trajectory runs. The lockstep session (frame and plant faults)
and the realtime one (process faults: SIGKILL, SIGSTOP, a dead emulator) are separate tests:
the realtime one runs in make test's last tier, alone on the machine."""

import json

import can
import pytest

from hil.faults import LOCKSTEP_CASES, REALTIME_CASES, run_matrix


def _passes(tmp_path, pacing, cases):
    doc = run_matrix(tmp_path, short=True, pacings=(pacing,))
    table = (tmp_path / "faults.md").read_text()
    assert doc["passed"], table
    assert {r["key"] for r in doc["cases"]} == {c.key for c in cases}
    for r in doc["cases"]:
        # case 9: every case that faulted came back to READY and ran the home move
        assert r["recovered"] in (None, True), r
    saved = json.loads((tmp_path / "faults.json").read_text())
    assert saved["passed"] and len(saved["cases"]) == len(doc["cases"])


@pytest.mark.hil
def test_the_lockstep_fault_matrix_passes_on_the_hexapod(tmp_path):
    _passes(tmp_path, "lockstep", LOCKSTEP_CASES)


@pytest.mark.realtime
def test_the_realtime_fault_matrix_passes_on_the_hexapod(tmp_path):
    _passes(tmp_path, "realtime", REALTIME_CASES)
    # the host records: SIGKILL of the controller and the emulator's death leave a log that
    # python-can reads to the end (the analysis above came from it)
    with can.LogReader(str(tmp_path / "faults-hexapod-realtime" / "run.blf")) as reader:
        assert sum(1 for _ in reader) > 10_000
