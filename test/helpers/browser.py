"""Headless Chromium driven over its DevTools protocol (a WebSocket; no driver to install): open a page, evaluate
JavaScript in it, take a screenshot. Debian's ``chromium`` package is installed with apt-get when it is missing
(the machines of this project are Debian and the tests run as root); :func:`chromium` fails, saying why, when it
cannot be had. Imports no rclpy.
"""
from __future__ import annotations

import base64
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

from websockets.sync.client import connect


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
    page's console errors and warnings are kept in ``console`` as (level, text), read as commands are sent."""

    def __init__(self, executable: str, log: Path, *, size: tuple[int, int] = (1280, 900),
                 webgl: bool = False) -> None:
        self.profile = tempfile.mkdtemp(prefix='chromium-profile-')
        self.log = log
        self._log_file = open(log, 'w')
        self.proc = subprocess.Popen(
            [executable, '--headless=new', '--no-sandbox', '--disable-dev-shm-usage', *(
                ['--use-angle=swiftshader', '--enable-unsafe-swiftshader', '--ignore-gpu-blocklist'] if webgl
                else ['--disable-gpu']),
             '--no-first-run', '--force-device-scale-factor=1', f'--window-size={size[0]},{size[1]}',
             '--remote-debugging-port=0', '--remote-debugging-address=127.0.0.1', f'--user-data-dir={self.profile}',
             'about:blank'], stdout=self._log_file, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
            start_new_session=True)
        url = self._devtools_url(60.0)
        self.ws = connect(url, max_size=None, open_timeout=30, legacy=True)
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

    def send(self, method: str, session: bool = False, timeout_s: float = 30.0, **params: Any) -> dict[str, Any]:
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

    def screenshot(self, path: Path) -> Path:
        data = self.send('Page.captureScreenshot', session=True, format='png')['data']
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
