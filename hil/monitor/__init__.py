"""`hydrapod monitor`: the operator's live view of the bus, or of a recorded log."""
