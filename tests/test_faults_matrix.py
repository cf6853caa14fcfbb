"""Issue 7: the fault-injection matrix's short form (every case on the hexapod, lockstep
and realtime sessions: emulator and controller as processes on the bus) passes: each
fault detected within its bound, held, and after RESET + ENABLE a trajectory runs."""

import json

import can

from hil.faults import LOCKSTEP_CASES, REALTIME_CASES, run_matrix


def test_the_short_fault_matrix_passes_on_the_hexapod(tmp_path):
    doc = run_matrix(tmp_path, short=True)
    table = (tmp_path / "faults.md").read_text()
    assert doc["passed"], table
    keys = {r["key"] for r in doc["cases"] if r["rig"] == "hexapod"}
    assert keys == {c.key for c in LOCKSTEP_CASES + REALTIME_CASES}
    for r in doc["cases"]:
        # case 9: every case that faulted came back to READY and ran the home move
        assert r["recovered"] in (None, True), r
    # the host records: SIGKILL of the controller and the emulator's death leave a log that
    # python-can reads to the end (the analysis above came from it)
    with can.LogReader(str(tmp_path / "faults-hexapod-realtime" / "run.blf")) as reader:
        assert sum(1 for _ in reader) > 10_000
    saved = json.loads((tmp_path / "faults.json").read_text())
    assert saved["passed"] and len(saved["cases"]) == len(doc["cases"])
