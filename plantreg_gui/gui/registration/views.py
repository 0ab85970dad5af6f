"""The workspace's views, in tab order: the one place a view is registered.

A view is a QWidget built from the :class:`~.session.RegistrationSession` that subscribes to the
session's events and tells it where the cursor is; it has a ``needs`` attribute ('raw',
'result' or 'cloud') that picks the note the workspace lays over it while it is empty. To add a
view: write its file and add one :class:`ViewSpec` line below.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

from PySide6.QtWidgets import QWidget

from .cloud_view import CloudView
from .image_views import RawImagesView, SideBySideView
from .masks_view import MasksView
from .mosaic_view import MosaicView


@dataclass(frozen=True)
class ViewSpec:
    key: str                                  # --view name
    title: str                                # tab title
    make: Callable[[object], QWidget]         # session -> view
    aliases: tuple[str, ...] = ()


VIEWS: tuple[ViewSpec, ...] = (
    ViewSpec("raw", "Raw images", RawImagesView),
    ViewSpec("side-by-side", "Side by side", SideBySideView, ("sidebyside", "side")),
    ViewSpec("mosaic", "Mosaic", lambda s: MosaicView().bind(s)),
    ViewSpec("masks", "Masks", lambda s: MasksView().bind(s), ("mask",)),
    ViewSpec("3d", "3D", lambda s: CloudView().bind(s), ("3-d", "cloud")),
)


def view_key(name: str) -> str | None:
    """The key of a view named ``name`` (key or alias, any case, '_' for '-'); None if unknown."""
    k = name.strip().lower().replace("_", "-")
    return next((v.key for v in VIEWS if k == v.key or k in v.aliases), None)
