"""Node loggers printing like ROS 2: ``[INFO] [<unix time>] [<logger name>]: message`` on stderr."""

from __future__ import annotations

import sys
import time
from typing import Any, TextIO

LEVELS = {"debug": 10, "info": 20, "warn": 30, "warning": 30, "error": 40, "fatal": 50, "unset": 0}
_LABEL = {10: "DEBUG", 20: "INFO", 30: "WARN", 40: "ERROR", 50: "FATAL"}

#: Logger name -> level; ``""`` is the default for every logger (``--log-level``).
_levels: dict[str, int] = {"": LEVELS["info"]}


def set_levels(levels: dict[str, str]) -> None:
    """Apply ``--log-level`` settings (``{"": "debug"}`` or ``{"controller_node": "warn"}``)."""
    for name, level in levels.items():
        _levels[name] = LEVELS[level.lower()]


class Logger:
    """rclpy-like logger: ``debug/info/warning/warn/error/fatal(msg, once=, throttle_duration_sec=)``."""

    def __init__(self, name: str, stream: TextIO | None = None) -> None:
        self.name = name
        self._stream = stream
        self._once: set[tuple[str, int]] = set()
        self._last: dict[tuple[str, int], float] = {}

    def get_child(self, suffix: str) -> Logger:
        """Logger ``<name>.<suffix>``."""
        return Logger(f"{self.name}.{suffix}" if self.name else suffix, self._stream)

    def get_effective_level(self) -> int:
        """Numeric threshold (10 debug .. 50 fatal)."""
        return _levels.get(self.name, _levels[""])

    def is_enabled_for(self, level: int) -> bool:
        """Whether a message of ``level`` would print."""
        return level >= self.get_effective_level()

    def log(self, level: int, message: str, *, once: bool = False, throttle_duration_sec: float | None = None,
            skip_first: bool = False, _depth: int = 1) -> bool:
        """Print ``message`` at ``level``; returns whether it was printed.

        ``once``, ``throttle_duration_sec`` and ``skip_first`` are tracked per call site,
        as in rclpy.
        """
        if not self.is_enabled_for(level):
            return False
        if once or throttle_duration_sec is not None or skip_first:
            frame = sys._getframe(_depth)
            site = (frame.f_code.co_filename, frame.f_lineno)
            if once:
                if site in self._once:
                    return False
                self._once.add(site)
            now = time.monotonic()
            last = self._last.get(site)
            if last is None and skip_first:
                self._last[site] = now
                return False
            if last is not None and throttle_duration_sec is not None and now - last < throttle_duration_sec:
                return False
            self._last[site] = now
        stamp = time.time_ns()
        label = _LABEL.get(level, "INFO")
        line = f"[{label}] [{stamp // 1_000_000_000}.{stamp % 1_000_000_000:09d}] [{self.name}]: {message}\n"
        stream = self._stream or sys.stderr
        try:
            stream.write(line)
            stream.flush()
        except (OSError, ValueError):  # closed stream at interpreter exit
            return False
        return True

    def debug(self, message: str, **kwargs: Any) -> bool:
        """Log at DEBUG."""
        return self.log(10, message, _depth=2, **kwargs)

    def info(self, message: str, **kwargs: Any) -> bool:
        """Log at INFO."""
        return self.log(20, message, _depth=2, **kwargs)

    def warning(self, message: str, **kwargs: Any) -> bool:
        """Log at WARN."""
        return self.log(30, message, _depth=2, **kwargs)

    def warn(self, message: str, **kwargs: Any) -> bool:
        """Log at WARN (rclpy alias)."""
        return self.log(30, message, _depth=2, **kwargs)

    def error(self, message: str, **kwargs: Any) -> bool:
        """Log at ERROR."""
        return self.log(40, message, _depth=2, **kwargs)

    def fatal(self, message: str, **kwargs: Any) -> bool:
        """Log at FATAL."""
        return self.log(50, message, _depth=2, **kwargs)


def get_logger(name: str) -> Logger:
    """A logger not tied to a node (``rclpy.logging.get_logger``)."""
    return Logger(name)
