"""What every hydrapod program needs at its edges, none of it physics or protocol: errors
from user input and their one-line report with exit code 2, TOML configuration files,
realtime scheduling of a process, and numba's kernel cache. Imports nothing of the project.
"""
