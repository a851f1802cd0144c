"""Headless Chromium driven over its DevTools protocol (a WebSocket; no driver to install): open a page, evaluate
JavaScript in it, wait until the page says it is ready, take a screenshot and cut an element's pixels out of it.
Debian's ``chromium`` package is installed with apt-get when it is missing
(the machines of this project are Debian and the tests run as root); :func:`chromium` fails, saying why, when it
cannot be had. Imports no rclpy.
"""
from __future__ import annotations

import base64
import io
import itertools
import json
import os
import re
import shutil
import subprocess
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib import image
from websockets.sync.client import connect

from helpers import PATIENCE_S  # re-exported: the view tests import it from here


def chromium() -> str:
    """The path of Debian's chromium, installed first if missing (apt-get update, apt-get install chromium).
    Raises RuntimeError with apt-get's output when it cannot be installed."""
    path = shutil.which('chromium')
    if path:
        return path
    env = dict(os.environ, DEBIAN_FRONTEND='noninteractive')
    out = ''
    for cmd in (['apt-get', 'update', '-q'], ['apt-get', 'install', '-y', '-q', '--no-install-recommends',
                                                  'chromium']):
        try:
            result = subprocess.run(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                                    timeout=900)
        except (OSError, subprocess.TimeoutExpired) as exc:
            raise RuntimeError(f'cannot install chromium: {" ".join(cmd)}: {exc}') from exc
        out += result.stdout[-2000:]
        if result.returncode:
            break
    path = shutil.which('chromium')
    if not path:
        raise RuntimeError(f'chromium is not installed and apt-get could not install it:\n{out}')
    return path


class Browser:
    """One headless Chromium with one page (a fixed viewport, 1280×900 unless ``size``, device scale 1). With
    ``webgl`` it renders WebGL in software (SwiftShader), for pages that draw 3D; otherwise the GPU is off. The
    page's console errors and warnings are kept in ``console`` as (level, text), read as commands are sent.
    Scrollbars are hidden: a page taller than the window is laid out as wide as one that fits, so a full-page
    screenshot (which takes the scrollbar away) shows the layout the element boxes were read from."""

    def __init__(self, executable: str, log: Path, *, size: tuple[int, int] = (1280, 900),
                 webgl: bool = False) -> None:
        self.profile = tempfile.mkdtemp(prefix='chromium-profile-')
        self.log = log
        self._log_file = open(log, 'w')
        self.proc = subprocess.Popen(
            [executable, '--headless=new', '--no-sandbox', '--disable-dev-shm-usage', *(
                ['--use-angle=swiftshader', '--enable-unsafe-swiftshader', '--ignore-gpu-blocklist'] if webgl
                else ['--disable-gpu']),
             '--no-first-run', '--hide-scrollbars', '--force-device-scale-factor=1',
             f'--window-size={size[0]},{size[1]}',
             '--remote-debugging-port=0', '--remote-debugging-address=127.0.0.1', f'--user-data-dir={self.profile}',
             'about:blank'], stdout=self._log_file, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
            start_new_session=True)
        url = self._devtools_url(60.0)
        # as the Foxglove test client: no keepalive pings, and events (console, page) buffered between commands
        # instead of a paused socket, however long a test goes between two commands
        self.ws = connect(url, max_size=None, max_queue=None, ping_interval=None, open_timeout=PATIENCE_S, legacy=True)
        self._ids = itertools.count(1)
        target = self.send('Target.createTarget', url='about:blank')['targetId']
        self.session = self.send('Target.attachToTarget', targetId=target, flatten=True)['sessionId']
        self.console: list[tuple[str, str]] = []
        self.send('Page.enable', session=True)
        self.send('Runtime.enable', session=True)

    def _devtools_url(self, timeout_s: float) -> str:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            match = re.search(r'DevTools listening on (ws://\S+)', self.log.read_text(errors='replace'))
            if match:
                return match.group(1)
            if self.proc.poll() is not None:
                break
            time.sleep(0.1)
        raise RuntimeError(f'chromium did not start its DevTools server:\n{self.log.read_text(errors="replace")}')

    def send(self, method: str, session: bool = False, timeout_s: float = PATIENCE_S, **params: Any) -> dict[str, Any]:
        """A DevTools command; its result (RuntimeError on an error)."""
        call_id = next(self._ids)
        msg: dict[str, Any] = {'id': call_id, 'method': method, 'params': params}
        if session:
            msg['sessionId'] = self.session
        self.ws.send(json.dumps(msg))
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            reply = json.loads(self.ws.recv(timeout=max(deadline - time.monotonic(), 0.01)))
            if reply.get('method') == 'Runtime.consoleAPICalled' and reply['params']['type'] in ('error', 'warning'):
                self.console.append((reply['params']['type'], ' '.join(
                    str(a.get('value', a.get('description', ''))) for a in reply['params'].get('args', []))))
            if reply.get('id') == call_id:
                if 'error' in reply:
                    raise RuntimeError(f'{method}: {reply["error"]}')
                return reply.get('result', {})
        raise RuntimeError(f'{method}: no reply in {timeout_s:g} s')

    def open(self, url: str) -> None:
        self.send('Page.navigate', session=True, url=url)

    def evaluate(self, expression: str) -> Any:
        """The value of a JavaScript expression in the page."""
        result = self.send('Runtime.evaluate', session=True, expression=expression, returnByValue=True)
        if 'exceptionDetails' in result:
            raise RuntimeError(f'{expression}: {result["exceptionDetails"]}')
        return result['result'].get('value')

    def wait_for(self, expression: str, timeout_s: float = PATIENCE_S) -> Any:
        """The value of a JavaScript expression once it is truthy, evaluated every 0.2 s; AssertionError, naming
        it, when it is not within ``timeout_s`` (a condition the page signals, not a time it takes)."""
        deadline = time.monotonic() + timeout_s
        while True:
            value = self.evaluate(expression)
            if value:
                return value
            assert time.monotonic() < deadline, f'not within {timeout_s:g} s: {expression} (last {value!r})'
            time.sleep(0.2)

    def box(self, selector: str) -> dict[str, float]:
        """The box of the element ``selector`` selects in page coordinates (left, top, width, height; CSS pixels,
        which at device scale 1 are the screenshot's)."""
        return self.evaluate(f'(() => {{ const r = document.querySelector({json.dumps(selector)})'
                             '.getBoundingClientRect(); return {left: r.left + window.scrollX, '
                             'top: r.top + window.scrollY, width: r.width, height: r.height}; })()')

    def screenshot(self, path: Path, *, full_page: bool = False) -> Path:
        """A PNG of the viewport, or with ``full_page`` of the whole page (what lies below the viewport too)."""
        params: dict[str, Any] = {'format': 'png'}
        if full_page:
            size = self.send('Page.getLayoutMetrics', session=True)['cssContentSize']
            params.update(captureBeyondViewport=True, clip={'x': 0, 'y': 0, 'width': size['width'],
                                                           'height': size['height'], 'scale': 1})
        data = self.send('Page.captureScreenshot', session=True, **params)['data']
        path.write_bytes(base64.b64decode(data))
        return path

    def close(self) -> None:
        try:
            self.ws.close()
        finally:
            self.proc.terminate()
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
            self._log_file.close()
            shutil.rmtree(self.profile, ignore_errors=True)


def crop(png: bytes, box: dict[str, float]) -> np.ndarray:
    """The RGB pixels (0..1) of a screenshot (PNG bytes) inside ``box`` (left, top, width, height in its pixels, as
    :meth:`Browser.box` or a page's getBoundingClientRect gives them); AssertionError when the box is not inside
    the screenshot (an element below the viewport, say), rather than an empty or partial region."""
    pixels = image.imread(io.BytesIO(png), format='png')[:, :, :3]
    top, left, height, width = int(box['top']), int(box['left']), int(box['height']), int(box['width'])
    region = pixels[max(top, 0):top + height, max(left, 0):left + width]
    assert height > 0 and width > 0 and abs(region.shape[0] - height) <= 1 and abs(region.shape[1] - width) <= 1, \
        f'the box {box} is not inside the {pixels.shape[1]}×{pixels.shape[0]} screenshot'
    return region
