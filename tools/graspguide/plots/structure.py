"""A figure described as JSON (what the tests compare instead of pixels): per axes its
title, axis labels, scales, limits (rounded), legend entries, the labels of its labelled
lines and its text annotations and shaded spans. Pixels change with fonts, FreeType and matplotlib
versions; this does not."""

from __future__ import annotations

from typing import Any


def _limits(lo: float, hi: float) -> list[float]:
    return [round(float(lo), 2), round(float(hi), 2)]


def axes_structure(ax: Any) -> dict[str, Any]:
    legend = ax.get_legend()
    return {
        "title": ax.get_title(loc="left") or ax.get_title(),
        "xlabel": ax.get_xlabel(),
        "ylabel": ax.get_ylabel(),
        "xscale": ax.get_xscale(),
        "yscale": ax.get_yscale(),
        "xlim": _limits(*ax.get_xlim()),
        "ylim": _limits(*ax.get_ylim()),
        "legend_title": legend.get_title().get_text() if legend else None,
        "legend": [t.get_text() for t in legend.get_texts()] if legend else [],
        "lines": [
            line.get_label() for line in ax.get_lines() if not line.get_label().startswith("_")
        ],
        "texts": [t.get_text() for t in ax.texts],
        # Shaded time spans (the hold window, the overview's session bands).
        "spans": [
            _limits(p.get_x(), p.get_x() + p.get_width())
            for p in ax.patches
            if hasattr(p, "get_width")
        ],
    }


def figure_structure(fig: Any) -> dict[str, Any]:
    """The JSON-able structure of ``fig``: its axes in order, with which share x."""
    axes = fig.get_axes()
    out = []
    for ax in axes:
        d = axes_structure(ax)
        shared = ax.get_shared_x_axes().get_siblings(ax)
        d["shares_x_with"] = sorted(axes.index(o) for o in shared if o is not ax)
        out.append(d)
    return {"axes_count": len(axes), "axes": out}


def svg_texts(svg: bytes) -> list[str]:
    """The text of every <text> element of an SVG written with svg.fonttype "none" (the
    labels as text, searchable and editable in a vector editor)."""
    import xml.etree.ElementTree as ET

    root = ET.fromstring(svg)
    out = []
    for el in root.iter():
        if el.tag.rsplit("}", 1)[-1] == "text":
            out.append("".join(el.itertext()))
    return out


__all__ = ["axes_structure", "figure_structure", "svg_texts"]
