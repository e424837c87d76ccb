"""Test helper: headless Chromium driven over the DevTools protocol: open a page, take screenshots.

Used by the browser test of ``dualarm view --web`` (test_view.py) and to take the screenshot in
docs/visualization.md. Chromium's one-shot ``--screenshot`` captures before a WebGL page has
drawn anything; over the DevTools websocket the page is loaded with ``Page.navigate`` and
captured with ``Page.captureScreenshot`` when wanted. With software rendering (SwiftShader)
the first capture of the Rerun viewer blocks 25-50 s; later ones take a fraction of a
second (``../shared/viz-notes.md``).
"""

from __future__ import annotations

import base64
import json
import shutil
import socket
import subprocess
import tempfile
import time
import urllib.request
from pathlib import Path
from types import TracebackType
from typing import Any, Self

from dualarm_control.app.view.server import stop_process
from dualarm_control.errors import DualArmError

CHROMIUM = "/usr/bin/chromium"
"""Debian's ``chromium`` package."""
FLAGS = (
    "--headless=new", "--no-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
    "--disable-background-networking", "--disable-component-update", "--disable-sync", "--no-first-run",
    "--disable-dev-shm-usage",
)


class BrowserError(DualArmError):
    """Chromium did not start, or a DevTools command failed."""


def free_port() -> int:
    """A TCP port free on 127.0.0.1 right now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class Chromium:
    """A headless Chromium process with one page, driven over its DevTools websocket.

    ``with Chromium() as browser: browser.navigate(url); png = browser.screenshot()``. The
    process, its profile directory and the websocket are closed on exit.
    """

    def __init__(self, width: int = 1280, height: int = 800, executable: str = CHROMIUM,
                 start_timeout: float = 30.0) -> None:
        self.port = free_port()
        self.profile = Path(tempfile.mkdtemp(prefix="dualarm-chromium-"))
        args = [executable, *FLAGS, f"--window-size={width},{height}", f"--remote-debugging-port={self.port}",
                "--remote-debugging-address=127.0.0.1", f"--user-data-dir={self.profile}", "about:blank"]
        self.log = (self.profile / "chromium.log").open("w")
        self.process = subprocess.Popen(args, stdout=self.log, stderr=subprocess.STDOUT)
        self._id = 0
        try:
            self.ws = self._connect(start_timeout)
        except BaseException:
            self.close()
            raise

    def _connect(self, timeout: float) -> Any:
        import websocket  # websocket-client (the test extra)

        deadline = time.monotonic() + timeout
        while True:
            if self.process.poll() is not None:
                raise BrowserError(f"chromium exited with {self.process.returncode}; see {self.profile / 'chromium.log'}")
            try:
                with urllib.request.urlopen(f"http://127.0.0.1:{self.port}/json", timeout=2) as reply:
                    pages = [t for t in json.load(reply) if t.get("type") == "page"]
                if pages:
                    return websocket.create_connection(pages[0]["webSocketDebuggerUrl"], timeout=120,
                                                       suppress_origin=True)
            except OSError:
                pass
            if time.monotonic() > deadline:
                raise BrowserError(f"no DevTools page on port {self.port} after {timeout:.0f} s")
            time.sleep(0.2)

    def send(self, method: str, params: dict[str, Any] | None = None, timeout: float = 120.0) -> dict[str, Any]:
        """Send a DevTools command and wait for its result (events in between are dropped)."""
        self._id += 1
        self.ws.settimeout(timeout)
        self.ws.send(json.dumps({"id": self._id, "method": method, "params": params or {}}))
        while True:
            reply = json.loads(self.ws.recv())
            if reply.get("id") == self._id:
                if "error" in reply:
                    raise BrowserError(f"{method}: {reply['error']}")
                result: dict[str, Any] = reply.get("result", {})
                return result

    def wait_event(self, method: str, timeout: float = 60.0) -> dict[str, Any]:
        """The parameters of the next DevTools event ``method`` (other messages are dropped)."""
        deadline = time.monotonic() + timeout
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                raise BrowserError(f"no {method} event within {timeout:.0f} s")
            self.ws.settimeout(left)
            message = json.loads(self.ws.recv())
            if message.get("method") == method:
                params: dict[str, Any] = message.get("params", {})
                return params

    def navigate(self, url: str, timeout: float = 60.0) -> None:
        """Load ``url`` in the page; returns on its load event (a WebGL app draws later than that)."""
        self.send("Page.enable")
        self.send("Page.navigate", {"url": url})
        self.wait_event("Page.loadEventFired", timeout)

    def screenshot(self, timeout: float = 120.0) -> bytes:
        """The page as a PNG (the first capture of a WebGL page can take tens of seconds)."""
        data = self.send("Page.captureScreenshot", {"format": "png"}, timeout=timeout)["data"]
        return base64.b64decode(data)

    def close(self) -> None:
        ws = getattr(self, "ws", None)
        if ws is not None:
            ws.close()
        stop_process(self.process)
        self.log.close()
        shutil.rmtree(self.profile, ignore_errors=True)

    def __enter__(self) -> Self:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()
