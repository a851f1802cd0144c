"""The shipped Foxglove layouts opened in a real Foxglove app: Lichtblick (the open-source Foxglove Studio), its web
build in headless Chromium with WebGL in software, connected to the live view's WebSocket server as a user connects
(``?ds=foxglove-websocket&ds.url=…``) and loading each installed layout (``layoutUrl=…``) while the program runs.

What it checks is what a user would see go wrong: a channel the app refuses (its "Player alert schema" console error:
a derived channel's JSON schema it cannot parse leaves the panel empty), a panel whose topic or path gives nothing,
and the 3D crane not drawn. The screenshots are saved in out/live_view/ (docs/figures/ holds copies of them).

Lichtblick's built app is in no registry (its npm packages are libraries): the test runs where a web build is, named
by LICHTBLICK_WEB (the directory of its index.html), and the test run says in one line when it is not (conftest).
"""
from __future__ import annotations

import functools
import os
import shutil
import threading
import time
from http.server import SimpleHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from urllib.parse import quote

import numpy as np
import pytest
from matplotlib import image

from crane_stiffness.launcher.rosrun import installed_config
from helpers import REPO
from helpers.browser import PATIENCE_S, Browser, chromium, crop
from helpers.live_rig import live_rig, wait_for_pairs

pytestmark = pytest.mark.lichtblick

SHOTS = REPO / 'out' / 'live_view'
SIZE = (1600, 900)


class _Handler(SimpleHTTPRequestHandler):
    """Lichtblick's files at /, the installed layouts at /layouts/ (one origin: the app fetches the layout)."""

    def __init__(self, *args, app: str, layouts: str, **kwargs):
        self.app, self.layouts = app, layouts
        super().__init__(*args, directory=app, **kwargs)

    def translate_path(self, path: str) -> str:
        if path.startswith('/layouts/'):
            return os.path.join(self.layouts, os.path.basename(path.split('?')[0]))
        return super().translate_path(path)

    def log_message(self, *args) -> None:
        pass


@pytest.fixture
def lichtblick(install_tree):
    """(base URL, server) serving LICHTBLICK_WEB and the install's layouts on a free loopback port."""
    install, _ = install_tree
    layouts = installed_config(install).parent / 'foxglove'
    handler = functools.partial(_Handler, app=os.environ['LICHTBLICK_WEB'], layouts=str(layouts))
    server = ThreadingHTTPServer(('127.0.0.1', 0), handler)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield f'http://127.0.0.1:{server.server_address[1]}'
    finally:
        server.shutdown()
        server.server_close()


def _panel(browser: Browser, title: str) -> dict:
    """The text of the panel whose toolbar shows ``title`` and the box of its largest canvas, where it draws (the
    legends and buttons are HTML beside or over it); an empty dict while the panel is not there."""
    return browser.evaluate(f"""(() => {{
        const header = [...document.querySelectorAll('header')]
            .find(h => h.innerText.trim().split('\\n')[0].trim() === {title!r});
        if (!header) return {{}};
        const panel = header.closest('.mosaic-tile') || header.parentElement;
        const canvases = [...panel.querySelectorAll('canvas')].map(c => c.getBoundingClientRect())
            .sort((a, b) => b.width * b.height - a.width * a.height);
        const r = canvases.length ? canvases[0] : {{top: 0, left: 0, width: 0, height: 0}};
        return {{top: r.top, left: r.left, width: r.width, height: r.height, text: panel.innerText}};
    }})()""")


def _open(browser: Browser, base: str, ws_url: str, layout: str, titles: list[str]) -> None:
    """Lichtblick at ``base`` connected to ``ws_url`` (token included, as a lab pastes it) with the installed
    ``layout``, until the panels ``titles`` are all on the page (the app loads for tens of seconds in software
    rendering)."""
    url = f'{base}/?ds=foxglove-websocket&ds.url={quote(ws_url, safe="")}&openIn=web' \
          f'&layoutUrl={quote(f"{base}/layouts/{layout}.json", safe="")}'
    browser.open(url)
    deadline = time.monotonic() + PATIENCE_S
    while not all(_panel(browser, t) for t in titles):
        if time.monotonic() > deadline:
            shot = browser.screenshot(browser.log.with_suffix('.png'))
            raise AssertionError(f'{layout}: panels {titles} not all shown (screenshot {shot}): {browser.console[-5:]}')
        time.sleep(0.5)


def _coloured(png: bytes, box: dict) -> int:
    """How many pixels of the panel's drawing are coloured (a plot's lines and points; its grid and text are grey)."""
    region = _pixels(png, box)
    return int((region.max(axis=-1) - region.min(axis=-1) > 0.3).sum())


def _dark(png: bytes, box: dict) -> int:
    """How many pixels of the 3D panel are dark (the overhead triangle, the labels; the empty scene is a blue grid on
    white)."""
    return int((_pixels(png, box).sum(axis=-1) < 1.2).sum())


def _problems(layout: str, png: bytes, panels: dict[str, dict]) -> list[str]:
    """What a user would see missing in ``layout`` (none: every panel shows what it should)."""
    problems = []
    if layout == 'stiffness_test':
        # The status the estimator publishes, shown by the indicator (its fallback, "no status", means no message).
        status = panels['Estimator status'].get('text', '').split()
        if not status or status[-1] not in ('OK', 'WARN'):
            problems.append(f'Estimator status shows {" ".join(status)!r}')
        dark = _dark(png, panels['3D crane (deflection exaggerated)'])
        if dark <= 300:
            problems.append(f'{dark} dark pixels in the 3D panel: the crane is not drawn')
        plotted = ('Force vs displacement: loading', 'Wire tensions [N]')
    else:
        plotted = ('Load cell [N, N·m]',)
    for title in plotted:
        coloured = _coloured(png, panels[title])
        if coloured <= 100:
            problems.append(f'{title}: {coloured} coloured pixels: nothing plotted')
    return problems


def _shown(browser: Browser, layout: str, titles: list[str], shot: Path) -> tuple[bytes, dict[str, dict], list[str]]:
    """The screenshot, the panels and what is missing, once nothing is (the panels fill while the program runs) or
    PATIENCE_S has passed (then what was still missing)."""
    deadline = time.monotonic() + PATIENCE_S
    while True:
        panels = {t: _panel(browser, t) for t in titles}
        png = browser.screenshot(shot).read_bytes()
        problems = _problems(layout, png, panels)
        if not problems or time.monotonic() > deadline:
            return png, panels, problems
        time.sleep(2.0)


def _pixels(png: bytes, box: dict) -> np.ndarray:
    return crop(png, box)[:, :-60]  # not the 3D panel's buttons


def test_layouts_open_in_lichtblick_every_channel_parsed_and_the_crane_drawn(install_tree, rclpy_context, tmp_path,
                                                                            lichtblick):
    install, env = install_tree
    path = chromium()
    # 25 times the side-force program (525 s): the program must still run when the second layout is shown,
    # however long the app takes to load in software rendering on a busy machine (each layout may wait out its
    # patience twice), since the plots follow the last 30 s and the crane model publishes the wire tensions only as
    # the commanded load changes: opened after the program, the tensions plot is empty. The rig stops as soon as
    # both layouts are checked. The app is served from an origin of its own: allowed as a lab allows the Foxglove or
    # Lichtblick web app.
    with live_rig(env, installed_config(install), tmp_path, rclpy_context, overrides={'load_program': {'repeats': 25}},
                  allowed_origins=lichtblick) as (procs, watcher, ports):
        wait_for_pairs(procs, watcher, 500)
        # The address as the node prints it for the Foxglove apps, the token in its query: what a lab pastes.
        ws_url = f'ws://127.0.0.1:{ports["port"]}/?token={ports["token"]}'
        shots = {}
        for layout, titles in (('stiffness_test', ['3D crane (deflection exaggerated)', 'Estimator status',
                                                   'Force vs displacement: loading', 'Wire tensions [N]']),
                               ('sensors', ['Load cell [N, N·m]', 'LVDT [m]', 'Command and applied load [N]'])):
            browser = Browser(path, tmp_path / f'chromium_{layout}.log', size=SIZE, webgl=True)
            try:
                _open(browser, lichtblick, ws_url, layout, titles)
                png, panels, problems = _shown(browser, layout, titles, tmp_path / f'lichtblick_{layout}.png')
                console = list(browser.console)
            finally:
                browser.close()
            refused = [text for level, text in console if 'Player alert schema' in text]
            assert not refused, f'{layout}: Lichtblick refused channels: {refused}'
            assert not problems, f'{layout}: {problems} (screenshot {tmp_path / f"lichtblick_{layout}.png"})'
            shots[layout] = (png, panels)
        procs.check_alive(allow_exit=('load_program',))
        log = procs.log('live_view')
    # The app connected from its own origin (allowed) and passed the token in the address: the front says so for
    # each of the two connections (without the token it logs "without the token: watching only").
    connected = [line for line in log.splitlines()
                 if f'(Origin {lichtblick})' in line and 'connected (with the token)' in line]
    assert len(connected) >= 2, [line for line in log.splitlines() if 'WebSocket' in line][-10:]
    SHOTS.mkdir(parents=True, exist_ok=True)
    for layout in shots:
        shutil.copy(tmp_path / f'lichtblick_{layout}.png', SHOTS / f'lichtblick_{layout}.png')
    png, panels = shots['stiffness_test']
    image.imsave(SHOTS / 'lichtblick_crane.png', _pixels(png, panels['3D crane (deflection exaggerated)']))
    assert Path(SHOTS / 'lichtblick_crane.png').stat().st_size > 0
