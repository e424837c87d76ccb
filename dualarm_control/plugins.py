"""A user's own limits and tasks, from their own files (``plugins`` parameter; docs/limits.md).

A plugin is a Python file (a path) or an importable module (a dotted name) that registers what it
defines when imported: ``@register_limit("name")`` (:mod:`dualarm_control.limits.registry`) for a
limit, ``@register_task("type")`` (:mod:`dualarm_control.tasks.registry`) for a task type. Loading the
same plugin twice imports it once.
"""

from __future__ import annotations

import hashlib
import importlib
import importlib.util
import sys
from collections.abc import Iterable
from pathlib import Path
from types import ModuleType

from dualarm_control.errors import ParameterError


def load_plugins(entries: Iterable[str], key: str = "plugins") -> list[ModuleType]:
    """Import every plugin named (empty strings skipped: ROS's ``[""]`` for none), in order.

    A ``.py`` path (absolute, or relative to the working directory) is imported under a name derived
    from its resolved path; anything else is imported as a module name. ParameterError naming ``key``
    and the entry when a file is missing or its import fails (the exception's text included)."""
    return [load_plugin(entry, key) for entry in entries if entry]


def load_plugin(entry: str, key: str = "plugins") -> ModuleType:
    """One plugin (see :func:`load_plugins`)."""
    if entry.endswith(".py") or "/" in entry:
        path = Path(entry).expanduser().resolve()
        if not path.is_file():
            raise ParameterError(key, entry, "a Python file that exists or an importable module name")
        name = f"dualarm_plugin_{path.stem}_{hashlib.sha1(str(path).encode()).hexdigest()[:8]}"
        if name in sys.modules:
            return sys.modules[name]
        spec = importlib.util.spec_from_file_location(name, path)
        assert spec is not None and spec.loader is not None
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module
        try:
            spec.loader.exec_module(module)
        except Exception as exc:
            del sys.modules[name]
            raise ParameterError(key, entry, f"a plugin that imports ({type(exc).__name__}: {exc})") from exc
        return module
    try:
        return importlib.import_module(entry)
    except Exception as exc:
        raise ParameterError(key, entry, f"a plugin that imports ({type(exc).__name__}: {exc})") from exc
