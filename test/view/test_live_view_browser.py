"""The live view's page in a real browser: headless Chromium (Debian's ``chromium``, installed by the test set-up
when missing) opens it while the program runs; the live estimate the page shows is the estimator's (read from the
DOM), the plot shows points (the screenshot is not blank there), the live k is shown with its two intervals, the
repeatability (the fit's 95 %) and the expanded uncertainty U (GUM, 95 %), in numbers and drawn, and E_n against the
model, and the screenshots are saved in out/live_view/ (docs/figures/ holds copies of them)."""
from __future__ import annotations

import json
import math
import re
import shutil
import time

import numpy as np
import pytest
from matplotlib import image

from crane_stiffness.launcher.rosrun import installed_config
from helpers import REPO
from helpers.browser import PATIENCE_S, Browser, crop
from helpers.live_rig import live_rig, wait_for_pairs

SHOTS = REPO / 'out' / 'live_view'
LOADING_BLUE = np.array([0x1f, 0x77, 0xb4]) / 255.0  # the page's colour of the loading points (style.css)




def test_page_shows_the_estimators_estimate_and_points(install_tree, rclpy_context, tmp_path, chromium_path):
    install, env = install_tree
    with live_rig(env, installed_config(install), tmp_path, rclpy_context) as (procs, watcher, ports):
        wait_for_pairs(procs, watcher, 2000)
        browser = Browser(chromium_path, tmp_path / 'chromium.log')
        try:
            browser.open(f'http://127.0.0.1:{ports["http_port"]}/')
            # what the page says it shows: an estimate and a status, the loading points drawn in the plot (100:
            # enough of them to see), and the crane drawn
            browser.wait_for("document.getElementById('k-loading')?.dataset.value && "
                             "document.getElementById('status-level').dataset.level || ''")
            browser.wait_for("Number(document.getElementById('xy').dataset.loadingPoints) >= 100 && "
                             "document.getElementById('scene').dataset.drawn === 'crane'")
            shown = browser.evaluate("(() => { const k = document.getElementById('k-loading');"
                                     " return [k.dataset.value, k.dataset.sampleStamp, k.textContent,"
                                     " document.getElementById('status-level').dataset.level,"
                                     " Object.keys(state.data).join(' ')]; })()")
            # the wires' table: one row per wire under its header, each tension as the last wires message gave it
            # (the page rewrites the rows' cells, it does not rebuild the table)
            browser.wait_for("document.getElementById('wires').rows.length === 7")
            table = browser.evaluate("(() => { const w = state.data.wires.wires, t = document.getElementById('wires');"
                                     " return w.map((x, i) => [x.name, x.slack, x.tension,"
                                     " t.rows[i + 1].cells[0].textContent, t.rows[i + 1].cells[1].dataset.value,"
                                     " t.rows[i + 1].cells[1].textContent]); })()")
            # the whole page: where the crane is depends on the fonts and on what the page shows (the side column
            # can wrap under the plot, the crane then lies below the window)
            # k with both intervals: the numbers (U and E_n from the estimator's status) and the drawing
            browser.wait_for("document.getElementById('U-loading').dataset.value && "
                             "document.getElementById('En-loading').dataset.value && "
                             "document.getElementById('kint').dataset.drawn === 'intervals'")
            intervals = browser.evaluate(
                "(() => { const v = (id) => document.getElementById(id).dataset.value;"
                " return [v('ki-loading'), v('rep-loading'), v('U-loading'), v('Uint-loading'), v('En-loading'),"
                " v('ki-model'), v('U-model'), document.getElementById('U-loading').textContent,"
                " document.getElementById('kint').dataset.intervals,"
                " document.getElementById('calibration').textContent]; })()")
            png = browser.screenshot(tmp_path / 'page.png', full_page=True).read_bytes()
            plot, crane = browser.box('#xy'), browser.box('#scene')
        finally:
            browser.close()
        procs.check_alive(allow_exit=('load_program',))
        # the watcher's thread may be a moment behind the view: until it has the estimate the page showed
        deadline = time.monotonic() + PATIENCE_S
        while shown[1] and float(shown[1]) not in watcher.values and time.monotonic() < deadline:
            time.sleep(0.05)
    value, stamp, text, level, channels = shown
    _check_intervals(intervals, watcher)
    assert [row[0] for row in table] == [f'wire_{i}' for i in range(1, 7)]
    for name, slack, tension, shown_name, shown_value, shown_text in table:  # the cells of the same message, or
        assert shown_name == name  # of one 0.1 s later (the page draws at most 10 times a second)
        assert shown_text == 'slack' if slack else shown_text.endswith(' N') and float(shown_value) > 0.0
    # the page's estimate is one the estimator published (the same number, for the same newest pair)
    assert watcher.values[float(stamp)] == float(value), (value, stamp)
    assert text.endswith(' N/m') and level is not None, (text, level, channels)
    plot_pixels = crop(png, plot)
    blue = np.all(np.abs(plot_pixels - LOADING_BLUE) < 0.08, axis=-1)
    assert blue.sum() > 200, f'{blue.sum()} pixels of loading points in the plot'
    crane_pixels = crop(png, crane)
    assert (crane_pixels.sum(axis=-1) < 2.0).sum() > 200  # the crane is drawn (dark lines on white)
    SHOTS.mkdir(parents=True, exist_ok=True)
    shutil.copy(tmp_path / 'page.png', SHOTS / 'page.png')
    image.imsave(SHOTS / 'crane.png', crane_pixels)


def _check_intervals(intervals: list, watcher) -> None:
    """The page's k, its repeatability and its U: the estimator's numbers, two intervals of visibly different width
    (U counts the sensors' calibrations: about 1.5 % of k; the repeatability of the window's pairs: a few hundredths
    of a percent over thousands, about 0.15 % over the hundred the page may show first on a slow machine), E_n
    within the model's and the measurement's U."""
    k, rep, big_u, u_interval, en, model, model_u, u_text, drawn, calibration = intervals
    k, big_u, en, model, model_u = map(float, (k, big_u, en, model, model_u))
    rep_low, rep_high = map(float, rep.split(','))
    u_low, u_high = map(float, u_interval.split(','))
    assert rep_low < k < rep_high and u_low < rep_low and rep_high < u_high
    assert u_low == pytest.approx(k - big_u) and u_high == pytest.approx(k + big_u)
    assert 0.005 * k < big_u < 0.05 * k, big_u  # the load cell's 1 % (k = 2) alone is 0.5 % of k
    assert big_u > 3 * (rep_high - rep_low) / 2  # (10 times from ~120 pairs on: read early, it was 10.0 once)
    assert abs(en) <= 1.0 and 0.03 * model < model_u < 0.1 * model  # the model's U: ~6 %, mostly the wires' E
    assert en == pytest.approx((k - model) / math.hypot(big_u, model_u), abs=0.05)  # (k from a later batch)
    assert 'k = 1.9' in u_text and 'declared calibrations' in calibration
    # the estimator stated that U in a status (4 significant digits)
    stated = {float(m) for s in watcher.status_history for _, text in s.values()
              for m in re.findall(r'U = ([0-9.]+) N/m', text)}
    assert float(f'{big_u:.4g}') in stated, (big_u, sorted(stated)[:5])
    pixels = json.loads(drawn)
    assert pixels['loading']['U_px'] > 5 * pixels['loading']['repeatability_px'], pixels
    assert pixels['loading']['U_px'] > 20 and pixels['model']['U_px'] > pixels['loading']['U_px'], pixels
