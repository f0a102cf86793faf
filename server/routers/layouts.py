"""Feature-point layouts for the landmark picker and the browser's face tracker: names,
regions, sides, mirror partners, a reference position for each point (on the built-in
sample face, cm, +y up, the face looking down +z), so the browser can show which point
comes next, and each point's MediaPipe face-mesh vertex (`mediapipe468`), so the
browser's tracker can read its 468 landmarks into the layout."""

from __future__ import annotations

from fastapi import APIRouter

from retarget.layouts import GROUPS, LAYOUTS, REGIONS, get_layout
from server.errors import responses

router = APIRouter(prefix="/api/layouts", tags=["layouts"], responses=responses())


def _layout_json(name: str) -> dict:
    layout = get_layout(name)
    reference = layout.reference_points().round(3).tolist()
    return {
        "name": layout.name,
        "description": layout.description,
        "n_points": layout.n_points,
        "points": [
            {"name": point, "region": region, "side": side, "mirror": mirror,
             "reference": xyz, "mediapipe468": i468}
            for point, region, side, mirror, xyz, i468 in zip(
                layout.point_names, layout.regions, layout.sides, layout.mirror, reference,
                layout.mediapipe468)
        ],
        "regions": list(REGIONS),
        "groups": {group: list(members) for group, members in GROUPS.items()},
    }


@router.get("")
def list_layouts() -> list[dict]:
    """Every built-in layout with its points."""
    return [_layout_json(name) for name in LAYOUTS]


@router.get("/{name}")
def get_layout_json(name: str) -> dict:
    """One layout; 422 naming the known ones for an unknown name."""
    return _layout_json(name)
