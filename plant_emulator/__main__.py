"""`python -m plant_emulator ...` is `hydrapod emulator ...`."""

import sys

from plant_emulator.commands import main

sys.exit(main())
