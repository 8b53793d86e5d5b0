"""What every figure of the analysis shares: matplotlib without a display (Agg), the resolution, the
stamp a smoke run puts on every title, and the atomic save.

    from hnn_analysis.plotting import save_figure     # before pyplot: it sets the Agg backend
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots()
    ...
    save_figure(fig, out / "figure.png")              # written whole or not at all, then closed
"""
from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from hnn.io import atomic_write  # noqa: E402

DPI = 150

# prefixed to every figure's title while set (reproduce.py --quick sets "QUICK ..."), so a smoke
# run's pictures are never mistaken for the paper's settings
STAMP = {"text": ""}


def set_stamp(text: str) -> None:
    """Prefix ``text`` to the title of every figure saved from now on ('' to stop)."""
    STAMP["text"] = text


def save_figure(fig, path) -> Path:
    """Write ``fig`` as a PNG at ``path`` atomically (its title stamped while ``set_stamp`` is on), then close it."""
    path = Path(path)
    if STAMP["text"]:
        old = fig._suptitle.get_text() if fig._suptitle is not None else ""
        fig.suptitle(f"{STAMP['text']}\n{old}" if old else STAMP["text"])
    atomic_write(path, lambda tmp: fig.savefig(tmp, format="png", dpi=DPI, bbox_inches="tight"))
    plt.close(fig)
    return path
