"""A picture of a dance's motifs: the sequence over time and the signature against its genre template.

Kept apart from ``motifs.py`` so that the model never imports matplotlib.
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from ..errors import InputError


def plot_motifs(result: dict, out_path: Path, *, title: str = "") -> None:
    """Draw ``motifs.dance_motifs``'s result to a PNG (or any format matplotlib writes by suffix)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..io.files import atomic_output

    k = result["k"]
    start = np.array([w["start_s"] for w in result["words"]])
    ids = np.array([int(w["motif"][1:]) for w in result["words"]])
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(12, 6.5), dpi=110, gridspec_kw={"height_ratios": [1, 1.2]})
    top.scatter(start, ids, c=ids, cmap="tab20", vmin=0, vmax=k - 1, s=18)
    top.set_xlabel("time (s)")
    top.set_ylabel("motif")
    top.set_ylim(-1, k)
    top.set_title(title or "motif sequence")
    x = np.arange(k)
    bottom.bar(x - 0.2, result["signature"], width=0.4, label="this dance", color="tab:blue")
    bottom.bar(x + 0.2, result["template"], width=0.4, label=f"{result['genre']} template", color="tab:orange")
    bottom.set_xticks(x[:: max(1, k // 24)], [f"M{i}" for i in x[:: max(1, k // 24)]], fontsize=7)
    bottom.set_ylabel("share of words")
    bottom.set_title(f"signature vs. {result['genre']} template: chi2 = {result['chi2']:.3f}")
    bottom.legend(fontsize=8)
    fig.tight_layout()
    # Render to memory first, so a format matplotlib does not know fails before any file exists.
    buf = io.BytesIO()
    try:
        fig.savefig(buf, format=Path(out_path).suffix.lower().lstrip(".") or "png")
    except ValueError as exc:
        raise InputError(f"cannot write a plot as {out_path}: {exc}; use .png, .pdf or .svg") from None
    finally:
        plt.close(fig)
    with atomic_output(out_path, "wb") as fh:
        fh.write(buf.getvalue())
