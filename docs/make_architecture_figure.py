"""Draw docs/architecture.png: the packages, their main modules and the one-way dependency arrows.

Run: ``.venv/bin/python docs/make_architecture_figure.py`` (matplotlib only; no package import)."""

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.patches import FancyArrowPatch, FancyBboxPatch  # noqa: E402

BOXES = {  # name: (x, y, w, h, lines)
    "bench": (0.5, 6.2, 9.0, 2.3, ["bench/", "acquisition/: protocols, excitations, runner, campaigns, compensation",
                                   "storage/: importers (CSV, MAT, EMPS, HSM150, Mnich), output files",
                                   "cli/: main.py, commands/   gui/   campaign_analysis/ (thin adapters)"]),
    "drivers": (0.5, 2.6, 4.2, 2.6, ["drivers/", "device interface (device.py)", "open_device(url): sim, serial,",
                                     "can, canopen (CiA 402), odrive", "wire protocol, links, host cycle"]),
    "analysis": (5.3, 2.6, 4.2, 2.6, ["analysis/", "record.py: load_record (the one loader)",
                                      "identification, models, skeleton, afrf,",
                                      "residual, presliding, compensation"]),
    "firmware_sim": (2.9, 0.1, 4.2, 1.7, ["firmware_sim/", "engine/: the C plant (plant.c, plant.py), drift",
                                          "devices/: simulated peers, own process, pty or CAN"]),
    "common": (0.5, -1.9, 9.0, 1.5, ["hilbench/common/  (bottom layer: all import it, it imports none)",
                                     "runfile/: schema, keys, DeviceIdentity, writer, reader   units.py: axis, mode",
                                     "metrics.py: nrmse, relative error, percent, names, verdict bands   errors.py"]),
}
ARROWS = [("bench", "drivers", "uses"), ("bench", "analysis", "uses"), ("analysis", "firmware_sim", "simulates with"),
          ("firmware_sim", "drivers", "protocol definitions only")]


OUT = Path(__file__).with_name("architecture.png")


def main(out: Path = OUT) -> None:
    fig, ax = plt.subplots(figsize=(10, 10.9))
    ax.set_xlim(0, 10)
    ax.set_ylim(-2.1, 8.8)
    ax.axis("off")
    centre = {}
    for name, (x, y, w, h, lines) in BOXES.items():
        ax.add_patch(FancyBboxPatch((x, y), w, h, boxstyle="round,pad=0.05", fc="#eef3fb", ec="#2c4f85", lw=1.5))
        ax.text(x + 0.15, y + h - 0.3, lines[0], fontsize=13, weight="bold", va="top", color="#2c4f85")
        for i, line in enumerate(lines[1:]):
            ax.text(x + 0.15, y + h - 0.8 - 0.38 * i, line, fontsize=9.5, va="top")
        centre[name] = (x + w / 2, y + h / 2, x, y, w, h)
    for a, b, label in ARROWS:
        ax_, ay, x0, y0, w0, h0 = centre[a]
        bx, by, x1, y1, w1, h1 = centre[b]
        start = (ax_, y0) if ay > by + 1 else (x0 if bx < ax_ else x0 + w0, ay)
        end = (bx, y1 + h1) if ay > by + 1 else (x1 + w1 if bx < ax_ else x1, by)
        if a == "firmware_sim":
            start, end = (x0 + 0.6, y0 + h0), (x1 + w1 / 2, y1)
        if a == "analysis" and b == "firmware_sim":
            start, end = (x0 + w0 / 2, y0), (x1 + w1 - 0.6, y1 + h1)
        ax.add_patch(FancyArrowPatch(start, end, arrowstyle="-|>", mutation_scale=18, lw=1.6, color="#333333"))
        ax.text((start[0] + end[0]) / 2 + 0.1, (start[1] + end[1]) / 2, label, fontsize=9, style="italic")
    ax.set_title("hilbench: packages and the one-way dependency rules (tests/test_import_contract.py checks them)",
                 fontsize=11)
    fig.savefig(out, dpi=90, bbox_inches="tight")


if __name__ == "__main__":
    main()
