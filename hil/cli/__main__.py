"""`python -m hil.cli ...` is `hydrapod ...`."""

import sys

from hil.cli import main

sys.exit(main())
