"""The workspace's views, in tab order: the one place a view is registered.

A view is a QWidget built from the :class:`~.session.RegistrationSession` that subscribes to the
session's events and tells it where the cursor is; it has a ``needs`` attribute ('raw',
'result' or 'cloud') that picks the note the workspace lays over it while it is empty. A view
may have these hooks, which the workspace calls on every view that has them (no view is named
anywhere else): ``on_shown()`` when its tab is shown, ``prepare_screenshot()`` before the window
is captured, ``view_rgb()`` -> (H, W, 3) uint8 for "Save view as PNG" (default: the widget as
drawn), ``shutdown()`` when the window closes.

To add a view: write its file and add one :class:`ViewSpec` line below. The ``--view`` choices of
``plantreg-gui`` and the lists in the README and docs/workspace.md come from here (a test
checks the documents).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable


def _raw(session):
    from .image_views import RawImagesView

    return RawImagesView(session)


def _side(session):
    from .image_views import SideBySideView

    return SideBySideView(session)


def _mosaic(session):
    from .mosaic_view import MosaicView

    return MosaicView().bind(session)


def _masks(session):
    from .masks_view import MasksView

    return MasksView().bind(session)


def _cloud(session):
    from .cloud_view import CloudView

    return CloudView().bind(session)


@dataclass(frozen=True)
class ViewSpec:
    key: str                                  # --view name
    title: str                                # tab title
    make: Callable[[object], object]          # session -> view (a QWidget; imported on demand)
    aliases: tuple[str, ...] = ()


VIEWS: tuple[ViewSpec, ...] = (
    ViewSpec("raw", "Raw images", _raw),
    ViewSpec("side-by-side", "Side by side", _side, ("sidebyside", "side")),
    ViewSpec("mosaic", "Mosaic", _mosaic),
    ViewSpec("masks", "Masks", _masks, ("mask",)),
    ViewSpec("3d", "3D", _cloud, ("3-d", "cloud")),
)


def view_keys() -> list[str]:
    return [v.key for v in VIEWS]


def view_key(name: str) -> str | None:
    """The key of a view named ``name`` (key or alias, any case, '_' for '-'); None if unknown."""
    k = name.strip().lower().replace("_", "-")
    return next((v.key for v in VIEWS if k == v.key or k in v.aliases), None)
