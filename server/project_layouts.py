"""The layouts a project can name: the built-in ones, the custom layouts it saved
(`ProjectStore.put_layout`) and the one its landmarks carry (``layout_spec``).

A custom layout is named ``custom-<hash>`` by the library (`retarget.custom_layouts`) and
resolved through a per-process registry; a request may arrive in a process that has not
seen it yet (after a restart), so the routers resolve a project's layout names here,
which registers the layout from what the project stored. Another project's layouts are
never resolved."""

from __future__ import annotations

from retarget.custom_layouts import layout_from_spec
from retarget.errors import RetargetError
from retarget.layouts import CUSTOM_NAME, LAYOUTS, Layout
from server.store import LayoutNotFound, ProjectStore

__all__ = ["resolve_layout"]


def resolve_layout(store: ProjectStore, project_id: str, name: str) -> Layout:
    """The layout `name` means in the project: a built-in layout, a custom layout it saved
    (by the name it was saved under or its ``custom-<hash>``), or its landmarks' own;
    `RetargetError` (-> 422) naming what it may be otherwise."""
    if not isinstance(name, str):
        raise RetargetError(f"a layout is named by a string, got {name!r:.80}")
    if name in LAYOUTS:
        return LAYOUTS[name]
    try:
        return layout_from_spec(store.layout(project_id, name)[1])
    except LayoutNotFound:
        pass
    landmarks = store.landmarks(project_id) if CUSTOM_NAME.fullmatch(name) else None
    if landmarks is not None and landmarks.get("layout") == name and landmarks.get("layout_spec"):
        return layout_from_spec(landmarks["layout_spec"])
    saved = [info["name"] for info in store.layouts(project_id)]
    raise RetargetError(
        f"unknown layout {name!r:.80}; available: {', '.join(LAYOUTS)}"
        + (f", and this project's custom layouts {', '.join(saved)}" if saved else
           " (this project has saved no custom layout)"))
