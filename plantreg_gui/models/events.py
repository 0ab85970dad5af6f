"""The one event mechanism of the models: an :class:`Event` is a list of callbacks
(``connect`` / ``disconnect`` / ``emit(*args)``, called in order on the emitting thread);
:class:`Events` is a model's named set of them (``model.events.<name>``).

Qt-free on purpose: models are tested without a display, and the views subscribe with plain
methods. Models emit on the GUI thread only (worker results are applied there), so no queued
delivery is needed.
"""

from __future__ import annotations

from typing import Any, Callable


class Event:
    """A minimal evented signal: ``connect(callback)``, ``disconnect(callback)``, ``emit(*args)``."""

    def __init__(self, name: str = "") -> None:
        self.name = name
        self._callbacks: list[Callable[..., Any]] = []

    def connect(self, callback: Callable[..., Any]) -> Callable[..., Any]:
        self._callbacks.append(callback)
        return callback

    def disconnect(self, callback: Callable[..., Any] | None = None) -> None:
        """Remove ``callback`` (every callback when None)."""
        if callback is None:
            self._callbacks.clear()
        elif callback in self._callbacks:
            self._callbacks.remove(callback)

    def emit(self, *args: Any) -> None:
        for cb in list(self._callbacks):
            cb(*args)


class Events:
    """A model's events, one attribute per name in ``NAMES`` (a subclass lists them)."""

    NAMES: tuple[str, ...] = ()

    def __init__(self) -> None:
        for n in self.NAMES:
            setattr(self, n, Event(n))


__all__ = ["Event", "Events"]
