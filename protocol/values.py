"""Signal values the DBC defines and more than one node interprets (one definition each)."""

# HOST_WAYPOINT_TIME.FLAGS bits
FLAG_LAST, FLAG_START, FLAG_STEP = 1, 2, 4
# CTRL_ACK.KIND: which host frame is acknowledged
KIND_HOST_CMD, KIND_WAYPOINT = 1, 2
# EMU_CTRL.COMMAND
EMU_SET_LOAD, EMU_INJECT, EMU_CLEAR, EMU_CLEAR_ALL = 1, 2, 3, 4
