"""matplotlib without a display: one place that selects the Agg backend."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt

LOAD_COLOURS = {0.0: "tab:blue", 3.0: "tab:orange", 6.0: "tab:green"}


def colour_for_load(load_kg: float) -> str:
    return LOAD_COLOURS.get(round(load_kg, 1), "tab:gray")


def save(fig, path) -> None:
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


__all__ = ["plt", "save", "colour_for_load"]
