"""`hydrapod hil faults`: the fault-injection matrix. Each case injects one fault into a
running system (emulator and controller as separate processes on the bus, this process the
host and recorder), measures the reaction from the recorded log and the emulator's ground
truth (EMU_TRUTH), and ends with RESET + ENABLE and a trajectory that must run normally.

A session is one emulator + controller pair on one rig and pacing, running its cases in
turn; the process cases (SIGKILL, SIGSTOP, a dead emulator) need realtime pacing and a
short valve SYNC watchdog (`VALVE_WATCHDOG_PERIODS`), the frame and plant cases run in lockstep (the same
cycles every run). Every case starts at rest at home with the controller READY, runs the
probe move (up 30 mm, back, 1.5 s each), injects its fault `INJECT_AT_S` into it, and
reads from the log:
- detection: cycles from the first affected SYNC to the controller's reaction (its first
  VALVE_CMD with M = 0, D = 0 for the e-stop), inclusive: a fault seen and acted on in the
  same cycle is 1; the reason from the next CTRL_STATUS. Persistent frame faults are
  judged on the cycles since the leg's last valid frame (what the configured counts count);
- excursion: the largest distance of the platform (the test bench's slide) from where it
  was at the injection, over `OBSERVE_S` after it (EMU_TRUTH, which keeps coming when the
  controller is dead: the emulator's plant runs on);
- transient faults: what the fault changed against the same probe without a fault: the
  largest change of the two probes' difference from the cycle before the injection over
  `TRANSIENT_WINDOW_S` (the probe's constant speed), judged on the legs (encoder strokes:
  the truth to one 0.125 mm count; cycles without the faulted leg's frame skipped) and
  reported for the platform. The difference before the injection is where each leg's
  stiction left it at rest (0.25-0.6 mm on the hexapod), never the fault's. On the hexapod
  1 mm of leg is 7-10 mm of platform horizontally, so the platform cannot carry a 1 mm
  criterion.
"""

from hil.faults.cases import LOCKSTEP_CASES, REALTIME_CASES, Case, CaseKind
from hil.faults.matrix import format_matrix, format_terminal, run_matrix, sessions

__all__ = ["LOCKSTEP_CASES", "REALTIME_CASES", "Case", "CaseKind", "format_matrix", "format_terminal", "run_matrix",
           "sessions"]
