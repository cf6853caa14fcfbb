"""Suite-wide settings: a deterministic Hypothesis profile, and a record of what pytest
collected so `test_suite_integrity` can prove nothing was silently left out."""

from program.numba_cache import configure

configure()     # before any kernel is defined (see program/numba_cache.py)

import pytest  # noqa: E402
from hypothesis import HealthCheck, settings  # noqa: E402

# Fixed seed (derandomize) so CI is reproducible; no deadline: timing is not behaviour.
settings.register_profile(
    "hydrapod",
    derandomize=True,
    deadline=None,
    database=None,
    suppress_health_check=[HealthCheck.too_slow],
)
settings.load_profile("hydrapod")


# the longest tiers first: with `make test`'s two workers, the VM and the HIL runs start at
# once instead of after everything else
TIER_ORDER = ("vm", "hil", "realtime")


def _tier(item) -> int:
    for rank, marker in enumerate(TIER_ORDER):
        if item.get_closest_marker(marker) is not None:
            return rank
    return len(TIER_ORDER)


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(session, config, items):
    # tryfirst: recorded before -k/-m deselection, so the record is what was collected.
    config.hydrapod_collected = [(str(item.path), getattr(item, "originalname", item.name)) for item in items]
    items.sort(key=_tier)            # stable: the files' own order within a tier
