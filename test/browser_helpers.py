"""Headless Chromium driven through the DevTools protocol (CDP), for the browser tests.

Chromium is started with a remote-debugging port of its own choosing, and spoken to over one
websocket (``websockets``' synchronous client) with flattened target sessions.
"""

from __future__ import annotations

import base64
import io
import json
import re
import shutil
import subprocess
import tempfile
import threading
import time

import numpy as np

__all__ = ['chromium_path', 'Browser']

_FLAGS = (
    '--headless=new',
    '--enable-unsafe-swiftshader',
    '--use-angle=swiftshader',
    '--no-sandbox',
    '--no-first-run',
    '--no-default-browser-check',
    '--disable-background-networking',
    '--disable-component-update',
    '--disable-sync',
    '--disable-extensions',
    '--mute-audio',
    '--remote-debugging-port=0',
)


def chromium_path() -> str | None:
    """The Chromium executable on PATH, or None."""
    for name in ('chromium', 'chromium-browser', 'google-chrome'):
        path = shutil.which(name)
        if path:
            return path
    return None


class Browser:
    """One headless Chromium with one page of ``width`` × ``height`` CSS pixels."""

    def __init__(self, executable: str, width: int = 1280, height: int = 800, timeout: float = 60.0) -> None:
        from websockets.sync.client import connect

        self.width, self.height = width, height
        self._profile = tempfile.mkdtemp(prefix='wmm-chromium-')
        self.proc = subprocess.Popen(
            [executable, *_FLAGS, f'--user-data-dir={self._profile}', f'--window-size={width},{height}', 'about:blank'],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
        )
        self.log = []
        found = threading.Event()
        url = []

        def read() -> None:
            for line in self.proc.stderr:
                self.log.append(line)
                match = re.search(r'DevTools listening on (ws://\S+)', line)
                if match and not url:
                    url.append(match.group(1))
                    found.set()

        threading.Thread(target=read, daemon=True).start()
        if not found.wait(timeout):
            self.close()
            raise RuntimeError('chromium did not start its DevTools endpoint:\n' + ''.join(self.log[-30:]))
        self._ws = connect(url[0], max_size=None, open_timeout=timeout)
        self._next_id = 0
        self.events = []
        target = self.call('Target.createTarget', {'url': 'about:blank'})['targetId']
        self.session = self.call('Target.attachToTarget', {'targetId': target, 'flatten': True})['sessionId']
        self.call('Page.enable', session=True)
        self.call(
            'Emulation.setDeviceMetricsOverride',
            {'width': width, 'height': height, 'deviceScaleFactor': 1, 'mobile': False},
            session=True,
        )

    def call(self, method: str, params: dict | None = None, session: bool = False, timeout: float = 60.0) -> dict:
        """Send one command and wait for its answer (events that come meanwhile are kept)."""
        self._next_id += 1
        message = {'id': self._next_id, 'method': method, 'params': params or {}}
        if session:
            message['sessionId'] = self.session
        self._ws.send(json.dumps(message))
        end = time.monotonic() + timeout
        while True:
            left = end - time.monotonic()
            if left <= 0:
                raise TimeoutError(f'no answer to {method} in {timeout} s')
            answer = json.loads(self._ws.recv(timeout=left))
            if answer.get('id') == self._next_id:
                if 'error' in answer:
                    raise RuntimeError(f'{method}: {answer["error"]}')
                return answer.get('result', {})
            self.events.append(answer)

    def navigate(self, url: str) -> None:
        self.call('Page.navigate', {'url': url}, session=True)

    def evaluate(self, expression: str):
        result = self.call('Runtime.evaluate', {'expression': expression, 'returnByValue': True}, session=True)
        return result.get('result', {}).get('value')

    def screenshot(self) -> np.ndarray:
        """The page as an (height, width, 3) uint8 RGB array."""
        from PIL import Image

        data = self.call('Page.captureScreenshot', {'format': 'png'}, session=True)['data']
        return np.asarray(Image.open(io.BytesIO(base64.b64decode(data))).convert('RGB'))

    def mouse(self, kind: str, x: float, y: float, buttons: int = 0) -> None:
        """One ``Input.dispatchMouseEvent``: kind 'mouseMoved', 'mousePressed' or 'mouseReleased'."""
        params = {'type': kind, 'x': float(x), 'y': float(y), 'buttons': buttons, 'pointerType': 'mouse'}
        if kind in ('mousePressed', 'mouseReleased'):
            params.update(button='left', clickCount=1)
        self.call('Input.dispatchMouseEvent', params, session=True)

    def drag(self, start: tuple[float, float], end: tuple[float, float], steps: int = 12, pause: float = 0.03) -> None:
        """Press the left button at ``start``, move to ``end`` in ``steps``, release there."""
        self.mouse('mouseMoved', *start)
        time.sleep(0.2)  # the page's hover state (a gizmo highlights)
        self.mouse('mousePressed', *start, buttons=1)
        for k in range(1, steps + 1):
            t = k / steps
            self.mouse('mouseMoved', start[0] + t * (end[0] - start[0]), start[1] + t * (end[1] - start[1]), buttons=1)
            time.sleep(pause)
        self.mouse('mouseReleased', *end)

    def close(self) -> None:
        try:
            if hasattr(self, '_ws'):
                self._ws.close()
        finally:
            if self.proc.poll() is None:
                self.proc.terminate()
                try:
                    self.proc.wait(timeout=10)
                except subprocess.TimeoutExpired:
                    self.proc.kill()
                    self.proc.wait()
            shutil.rmtree(self._profile, ignore_errors=True)
