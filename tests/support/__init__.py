"""What the tests share: the controller against the emulated rig in process (loops.py), the
command run in process (cli.py), the allocation probe (alloc.py), buses and scripted peers
(buses.py, bus_peer.py), and the probe of compiled kernels (first_motion_probe.py)."""
