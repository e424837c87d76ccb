"""The Rerun web viewer served on this machine only (127.0.0.1), by the ``rerun`` binary of the wheel.

``rr.serve_grpc`` and ``rr.serve_web_viewer`` listen on every interface (0.0.0.0); the
``rerun`` command has ``--bind``. So ``dualarm view --web`` starts ``rerun --serve-web --bind
127.0.0.1`` (a gRPC proxy that buffers what it receives for late viewers, and the web viewer,
which ships in the wheel and runs offline) and logs into it with ``connect_grpc``.
"""

from __future__ import annotations

import os
import socket
import subprocess
import time
import urllib.parse
from pathlib import Path
from types import TracebackType
from typing import Self

from dualarm_control.errors import DualArmError

HOST = "127.0.0.1"
DEFAULT_GRPC_PORT = 9876
DEFAULT_WEB_PORT = 9090


def rerun_executable() -> Path:
    """The ``rerun`` binary inside the rerun-sdk wheel (``RERUN_CLI_PATH`` overrides it)."""
    if "RERUN_CLI_PATH" in os.environ:
        return Path(os.environ["RERUN_CLI_PATH"])
    try:
        import rerun_cli
    except ImportError:
        raise DualArmError("the Rerun viewer is not installed: pip install 'dualarm_control[view]'") from None
    return Path(rerun_cli.__file__).parent / "rerun"


def _listening(port: int) -> bool:
    with socket.socket() as s:
        s.settimeout(0.5)
        return s.connect_ex((HOST, port)) == 0



def stop_process(process: subprocess.Popen[bytes], grace_s: float = 10.0) -> None:
    """SIGTERM ``process`` if it still runs, SIGKILL it after ``grace_s`` [s], and reap it."""
    if process.poll() is None:
        process.terminate()
        try:
            process.wait(timeout=grace_s)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait(timeout=grace_s)

class WebViewer:
    """``rerun --serve-web`` on 127.0.0.1: its gRPC proxy URL (to log into) and the page URL."""

    def __init__(self, grpc_port: int = DEFAULT_GRPC_PORT, web_port: int = DEFAULT_WEB_PORT,
                 log_path: Path | None = None, timeout: float = 20.0) -> None:
        for port in (grpc_port, web_port):
            if _listening(port):
                raise DualArmError(f"port {port} on {HOST} is in use (another viewer?): choose --grpc-port/--web-port")
        self.grpc_port, self.web_port = grpc_port, web_port
        out = log_path.open("w") if log_path is not None else subprocess.DEVNULL
        self.process = subprocess.Popen(
            [str(rerun_executable()), "--serve-web", "--bind", HOST, "--port", str(grpc_port),
             "--web-viewer-port", str(web_port)],
            stdout=out, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)
        deadline = time.monotonic() + timeout
        while not (_listening(grpc_port) and _listening(web_port)):
            if self.process.poll() is not None or time.monotonic() > deadline:
                self.close()
                raise DualArmError(f"rerun --serve-web did not listen on {HOST}:{grpc_port}/{web_port} "
                                   f"within {timeout:.0f} s")
            time.sleep(0.1)

    @property
    def grpc_url(self) -> str:
        """What the SDK connects to (``RecordingStream.connect_grpc``)."""
        return f"rerun+http://{HOST}:{self.grpc_port}/proxy"

    @property
    def url(self) -> str:
        """The page to open in a browser (WebGL renderer: WebGPU is often missing)."""
        return f"http://{HOST}:{self.web_port}/?url={urllib.parse.quote(self.grpc_url, safe='')}&renderer=webgl"

    def close(self) -> None:
        stop_process(self.process)

    def __enter__(self) -> Self:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()
