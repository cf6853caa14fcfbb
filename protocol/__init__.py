"""hydrapod CAN protocol: the DBC, codecs compiled from it, E2E protection, buses, bus budget.

`hydrapod.dbc` beside this file is the single source of truth for every frame. Nothing
here runs physics or control; the controller and the emulator build on it.
"""
