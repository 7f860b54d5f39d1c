"""Regenerate the GUI screenshots in docs/: ``python docs/make_screenshots.py [--out docs]``.

Runs the real operator window offscreen, at 1280x800 (the smallest screen the layout is made for),
against the simulated device (``sim://``): a short identification run (screenshot during the run), then
the run browser on the file it wrote, with the identification analysis (screenshots of the channels and
of the analysis), then the device-settings tab, and the campaign tab's Results after its *Analyse* button ran
``hilbench analyse`` on a small campaign (12 simulated identification runs written by
bench.campaign_analysis.synthetic, with a wear step at run 8: no device needed). Nothing is staged: what the PNGs
show is what the GUI shows.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")

SHOTS = ("gui-live-run.png", "gui-run-browser.png", "gui-analysis.png", "gui-device-settings.png",
         "gui-campaign.png")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path(__file__).resolve().parent, help="folder for the PNGs")
    args = ap.parse_args(argv)

    from PySide6 import QtTest, QtWidgets

    from hilbench.bench.campaign_analysis.synthetic import SyntheticCampaign, write_campaign
    from hilbench.bench.gui.app import qt_problem
    from hilbench.bench.gui.main_window import MainWindow
    from hilbench.firmware_sim.engine.drift import Drift

    problem = qt_problem()
    if problem:
        print(f"make_screenshots: {problem}", file=sys.stderr)
        return 2
    _app = QtWidgets.QApplication.instance() or QtWidgets.QApplication([])  # noqa: F841 - keep it alive

    def spin(cond, timeout: float) -> bool:
        end = time.monotonic() + timeout
        while not cond() and time.monotonic() < end:
            QtTest.QTest.qWait(10)  # an event loop that sleeps, like app.exec()
        return cond()

    args.out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as runs:
        window = MainWindow(runs_dir=runs)
        window.resize(1280, 800)
        window.show()
        try:
            window.connect_device("sim://")
            if not spin(lambda: window.connected, 20):
                print(f"make_screenshots: cannot connect: {window.messages[-1][1]}", file=sys.stderr)
                return 1
            # 0.5 s device watchdog (the default; set here in case a config file lowers it): a busy shared machine
            # can starve the host of 0.1 s
            window.protocol.device_form.set_value("watchdog_timeout", "0.5")
            form = window.protocol.select("identification")
            for key, value in {"duration": "5", "amplitude": "8", "period": "1", "cutoff": "100"}.items():
                form.set_value(key, value)
            window.protocol.operator_edit.setText("docs")
            window.protocol.notes_edit.setText("make_screenshots.py")
            out = str(Path(runs) / "identification-demo.h5")
            window.protocol.out_edit.setText(out)
            window.protocol.start_button.click()
            spin(lambda: window.live.buffer.total > 30000, 10)  # 3 s of the 5 s run on screen
            spin(lambda: "frames/s" in window.live.rate_label.text(), 2)
            window.grab().save(str(args.out / SHOTS[0]))
            if not spin(lambda: window.run_worker is None, 20):
                print("make_screenshots: the run did not finish", file=sys.stderr)
                return 1
            window.tabs.setCurrentWidget(window.browser)
            window.browser.refresh_files()
            window.browser.open(out)
            spin(lambda: False, 0.3)
            window.grab().save(str(args.out / SHOTS[1]))
            window.browser.analyse("identification")
            if not spin(lambda: window.browser.last_result is not None, 60):
                print(f"make_screenshots: analysis failed: {window.messages[-1][1]}", file=sys.stderr)
                return 1
            spin(lambda: False, 0.3)
            window.grab().save(str(args.out / SHOTS[2]))
            window.protocol.tabs.setCurrentIndex(1)
            spin(lambda: False, 0.3)
            window.grab().save(str(args.out / SHOTS[3]))
            window.protocol.tabs.setCurrentIndex(0)
            window.tabs.setCurrentWidget(window.campaign)
            campaign = Path(runs) / "campaign"
            write_campaign(campaign, SyntheticCampaign(runs=12, duration=1.0, drift=Drift(wear_step=0.08),
                                                       wear_step_at_run=8))
            window.campaign.out_edit.setText(str(campaign))
            window.campaign.analyse_options = ("--serial", "--no-dashboard")  # 12 short runs: no cluster
            window.campaign.analyse_button.click()
            if not spin(lambda: window.campaign.command is None, 120) or window.campaign.results.table.rowCount() != 12:
                print(f"make_screenshots: analyse failed: {window.campaign.status.text()}", file=sys.stderr)
                return 1
            spin(lambda: False, 0.3)
            window.grab().save(str(args.out / SHOTS[4]))
        finally:
            window.shutdown()
    for name in SHOTS:
        print(args.out / name)
    return 0


if __name__ == "__main__":
    sys.exit(main())
