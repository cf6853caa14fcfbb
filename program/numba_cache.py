"""Where numba keeps compiled kernels: one directory per version of the project's sources.

numba's on-disk cache checks only the source file of the function it compiled, not the
kernels that function calls in other modules, so an edit to a callee would keep a stale
caller running. The cache directory is therefore named after a digest of every source
file of the project's packages. A `NUMBA_CACHE_DIR` set by the user wins.

numba binds a kernel to its cache directory when the kernel is defined (at import), so each
entry point (`python -m firmware_py`, `python -m plant_emulator`, `hydrapod`, the tests)
calls `configure()` before it imports any module that defines kernels.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("program", "physics", "protocol", "firmware_py", "plant_emulator", "hil")
CACHE_ROOT = ROOT / ".numba-cache"


def sources_digest() -> str:
    digest = hashlib.sha256()
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            digest.update(str(path.relative_to(ROOT)).encode())
            digest.update(path.read_bytes())
    return digest.hexdigest()[:16]


def configure(prune: bool = True) -> Path | None:
    """Point numba at this version's cache directory; with `prune`, remove the directories
    of other versions. Returns the directory (None when the user chose one)."""
    if "NUMBA_CACHE_DIR" in os.environ:
        return None
    current = CACHE_ROOT / sources_digest()
    os.environ["NUMBA_CACHE_DIR"] = str(current)
    if "numba" in sys.modules:              # imported already: its config has been read
        sys.modules["numba"].config.CACHE_DIR = str(current)
    if prune and CACHE_ROOT.is_dir():
        for old in CACHE_ROOT.iterdir():
            if old != current:
                shutil.rmtree(old, ignore_errors=True)
    return current
