"""Hardware-in-the-loop: scenarios, the runner that launches emulator and controller as
separate processes on a fresh bus, logs, metrics, plots and reports.
This package also holds the `hydrapod` command-line entry point.
"""
