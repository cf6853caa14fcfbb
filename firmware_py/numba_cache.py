"""Where numba keeps its compiled kernels: one directory per version of the sources.

numba's on-disk cache checks only the file of the function it compiled, not the kernels
that function calls from other modules: after an edit to `plant_emulator/hydraulics.py`
the cached `rigs.legs_hydraulics` kept running the old `chamber_step` (a whole session of
fault measurements was taken on stale physics). So the cache directory is named after a
digest of every source file that holds kernels; an edit anywhere gives a fresh directory,
and the directories of older sources are removed. A NUMBA_CACHE_DIR set by the user wins.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
KERNEL_PACKAGES = ("firmware_py", "plant_emulator")
CACHE_ROOT = ROOT / ".numba-cache"


def sources_digest() -> str:
    digest = hashlib.sha256()
    for package in KERNEL_PACKAGES:
        for path in sorted((ROOT / package).glob("*.py")):
            digest.update(path.name.encode())
            digest.update(path.read_bytes())
    return digest.hexdigest()[:16]


def configure() -> None:
    if "NUMBA_CACHE_DIR" in os.environ:
        return
    current = CACHE_ROOT / sources_digest()
    os.environ["NUMBA_CACHE_DIR"] = str(current)
    if "numba" in sys.modules:              # imported first elsewhere: its config is already read
        sys.modules["numba"].config.CACHE_DIR = str(current)
    if CACHE_ROOT.is_dir():
        for old in CACHE_ROOT.iterdir():
            if old != current:
                shutil.rmtree(old, ignore_errors=True)
