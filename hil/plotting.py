"""matplotlib without a display: one place that selects the Agg backend.

`plt` is pyplot, imported on first use: a HIL run's host (and every scenario import) starts
without matplotlib, which costs 0.4 s here and a minute in the SocketCAN VM."""

from __future__ import annotations

LOAD_COLOURS = {0.0: "tab:blue", 3.0: "tab:orange", 6.0: "tab:green"}


class _Pyplot:
    """matplotlib.pyplot with the Agg backend, loaded at the first attribute read."""

    _module = None

    def __getattr__(self, name: str):
        if _Pyplot._module is None:
            import matplotlib
            matplotlib.use("Agg")
            import matplotlib.pyplot as pyplot
            _Pyplot._module = pyplot
        return getattr(_Pyplot._module, name)


plt = _Pyplot()


def colour_for_load(load_kg: float) -> str:
    return LOAD_COLOURS.get(round(load_kg, 1), "tab:gray")


def save(fig, path) -> None:
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


__all__ = ["plt", "save", "colour_for_load"]
