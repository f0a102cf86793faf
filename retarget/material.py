"""A mesh's surface material, the part of glTF's metallic-roughness material that is kept.

`Material` holds what a face needs to look like itself in an exported glTF: the base
colour (factor and texture), metallic and roughness factors, alpha mode and whether it is
double-sided. Normal, occlusion, emissive and metallic-roughness maps are not kept.
`material_from_trimesh` reads it from what trimesh loads of a glTF/GLB primitive.
"""

from __future__ import annotations

import io
from dataclasses import dataclass

import numpy as np

from retarget.errors import RetargetError

ALPHA_MODES = ("OPAQUE", "MASK", "BLEND")


@dataclass(frozen=True)
class Material:
    """glTF 2.0 metallic-roughness material values (defaults are glTF's).

    name : the material's name.
    base_color : (r, g, b, a) linear factors in [0, 1].
    metallic, roughness : factors in [0, 1].
    double_sided : draw back faces.
    alpha_mode : one of `ALPHA_MODES`.
    base_color_texture : the base colour image as PNG bytes, or None; it is sampled with
        the mesh's uv.
    """

    name: str = ""
    base_color: tuple[float, float, float, float] = (1.0, 1.0, 1.0, 1.0)
    metallic: float = 1.0
    roughness: float = 1.0
    double_sided: bool = False
    alpha_mode: str = "OPAQUE"
    base_color_texture: bytes | None = None

    def __post_init__(self):
        color = tuple(float(c) for c in self.base_color)
        factors = (*color, float(self.metallic), float(self.roughness))
        if len(color) != 4 or not all(0.0 <= f <= 1.0 for f in factors):
            raise RetargetError(f"material {self.name!r}: base colour (4 values), metallic and "
                                f"roughness must lie in [0, 1]; got {color}, {self.metallic}, "
                                f"{self.roughness}")
        if self.alpha_mode not in ALPHA_MODES:
            raise RetargetError(f"material {self.name!r}: alpha mode must be one of "
                                f"{', '.join(ALPHA_MODES)}; got {self.alpha_mode!r}")
        object.__setattr__(self, "base_color", color)


def material_from_trimesh(visual) -> Material | None:
    """The `Material` of a trimesh visual loaded from glTF (a PBRMaterial), else None.

    trimesh stores the base colour factor as 8 bits per channel, so it comes back
    rounded to 1/255; the texture image is re-encoded as PNG (lossless from the decoded
    pixels).
    """
    material = getattr(visual, "material", None)
    if type(material).__name__ != "PBRMaterial":
        return None
    color = np.asarray((1.0, 1.0, 1.0, 1.0) if material.baseColorFactor is None
                       else material.baseColorFactor)
    if color.dtype.kind in "ui":  # trimesh's 8-bit storage
        color = color / 255.0
    texture = None
    if material.baseColorTexture is not None:
        buffer = io.BytesIO()
        material.baseColorTexture.save(buffer, format="PNG")
        texture = buffer.getvalue()
    return Material(
        name=material.name or "",
        base_color=tuple(float(c) for c in color),
        metallic=1.0 if material.metallicFactor is None else float(material.metallicFactor),
        roughness=1.0 if material.roughnessFactor is None else float(material.roughnessFactor),
        double_sided=bool(material.doubleSided),
        alpha_mode=material.alphaMode or "OPAQUE",
        base_color_texture=texture,
    )
