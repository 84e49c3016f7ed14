"""Writes docs/foxglove_layout.json: the layout for cdprctl's live view and recordings — the
3D panel (the scene in the base frame), the cable tensions and the tracking error plotted from
``/signals``, and the log. Built with foxglove-sdk's layout classes, so the file is what
Foxglove itself reads. Run: ``.venv/bin/python tools/foxglove_layout.py [CABLES]`` (default 8)."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import foxglove.layouts as fl

OUT = Path(__file__).resolve().parents[1] / "docs" / "foxglove_layout.json"


def layout(cables: int) -> fl.Layout:
    tensions = fl.PlotPanel(title="cable tensions (N)", config=fl.PlotConfig(
        paths=[fl.PlotSeries(value=f"/signals.tensions[{i}]", label=f"cable {i + 1}")
               for i in range(cables)],
        show_legend=True))  # fmt: skip
    error = fl.PlotPanel(title="tracking error (m, rad)", config=fl.PlotConfig(
        paths=[fl.PlotSeries(value=f"/signals.tracking_error[{i}]", label=a)
               for i, a in enumerate(("x", "y", "z", "rx", "ry", "rz"))],
        show_legend=True))  # fmt: skip
    scene = fl.ThreeDeePanel(title="cdprctl", config=fl.ThreeDeeConfig(
        follow_tf="base", fixed_frame="base", follow_mode="follow-none"))  # fmt: skip
    log = fl.LogPanel(config=fl.LogConfig(topic_to_render="/log"))
    return fl.Layout(content=fl.SplitContainer(direction="row", items=[
        fl.SplitItem(proportion=3, content=scene),
        fl.SplitItem(proportion=2, content=fl.SplitContainer(direction="column", items=[
            fl.SplitItem(proportion=2, content=tensions),
            fl.SplitItem(proportion=1, content=error),
            fl.SplitItem(proportion=1, content=log),
        ])),
    ]))  # fmt: skip


if __name__ == "__main__":
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 8
    text = layout(n).to_json()
    OUT.write_text(json.dumps(json.loads(text), indent=1) + "\n")
    print(f"wrote {OUT}")
