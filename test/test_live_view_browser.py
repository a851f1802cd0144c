"""The live view's page in a real browser: headless Chromium (Debian's ``chromium``, installed by the test set-up
when missing) opens it while the program runs; the live estimate the page shows is the estimator's (read from the
DOM), the plot shows points (the screenshot is not blank there), and the screenshots are saved in out/live_view/
(docs/figures/ holds copies of them)."""
from __future__ import annotations

import io
import shutil
import time

import numpy as np
import pytest
from matplotlib import image

from crane_stiffness.launcher.rosrun import installed_config
from helpers import REPO
from helpers.browser import Browser, chromium
from helpers.live_rig import live_rig, wait_for_pairs

SHOTS = REPO / 'out' / 'live_view'
LOADING_BLUE = np.array([0x1f, 0x77, 0xb4]) / 255.0  # the page's colour of the loading points (style.css)


@pytest.fixture(scope='module')
def chromium_path() -> str:
    try:
        return chromium()
    except RuntimeError as exc:  # the check cannot be made without it: a failure, never a skip
        pytest.fail(f'headless Chromium is needed for the page test: {exc}')


def _region(png: bytes, rect: dict) -> np.ndarray:
    pixels = image.imread(io.BytesIO(png), format='png')[:, :, :3]
    top, left = int(rect['top']), int(rect['left'])
    return pixels[top:top + int(rect['height']), left:left + int(rect['width'])]


def test_page_shows_the_estimators_estimate_and_points(install_tree, rclpy_context, tmp_path, chromium_path):
    install, env = install_tree
    with live_rig(env, installed_config(install), tmp_path, rclpy_context) as (procs, watcher, ports):
        wait_for_pairs(procs, watcher, 2000)
        browser = Browser(chromium_path, tmp_path / 'chromium.log')
        try:
            browser.open(f'http://127.0.0.1:{ports["http_port"]}/')
            deadline = time.monotonic() + 60
            while not browser.evaluate("document.getElementById('k-loading')?.dataset.value && "
                                       "document.getElementById('status-level').dataset.level || ''"):
                assert time.monotonic() < deadline, 'the page shows no estimate'
                time.sleep(0.2)
            time.sleep(4.0)  # the program goes on: points, fit and crane under load
            shown = browser.evaluate("(() => { const k = document.getElementById('k-loading');"
                                     " return [k.dataset.value, k.dataset.sampleStamp, k.textContent,"
                                     " document.getElementById('status-level').dataset.level,"
                                     " Object.keys(state.data).join(' ')]; })()")
            png = browser.screenshot(tmp_path / 'page.png').read_bytes()
            plot = browser.evaluate("JSON.parse(JSON.stringify(document.getElementById('xy')"
                                    ".getBoundingClientRect()))")
            crane = browser.evaluate("JSON.parse(JSON.stringify(document.getElementById('scene')"
                                     ".getBoundingClientRect()))")
        finally:
            browser.close()
        procs.check_alive(allow_exit=('load_program',))
    value, stamp, text, level, channels = shown
    # the page's estimate is one the estimator published (the same number, for the same newest pair)
    assert watcher.values[float(stamp)] == float(value), (value, stamp)
    assert text.endswith(' N/m') and level is not None, (text, level, channels)
    plot_pixels = _region(png, plot)
    blue = np.all(np.abs(plot_pixels - LOADING_BLUE) < 0.08, axis=-1)
    assert blue.sum() > 200, f'{blue.sum()} pixels of loading points in the plot'
    crane_pixels = _region(png, crane)
    assert (crane_pixels.sum(axis=-1) < 2.0).sum() > 200  # the crane is drawn (dark lines on white)
    SHOTS.mkdir(parents=True, exist_ok=True)
    shutil.copy(tmp_path / 'page.png', SHOTS / 'page.png')
    image.imsave(SHOTS / 'crane.png', crane_pixels)
