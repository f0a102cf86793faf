"""A mesh's surface material, the part of glTF's metallic-roughness material that is kept.

`Material` holds what a face needs to look like itself in an exported glTF: the base
colour (factor and texture), metallic and roughness factors, alpha mode and whether it is
double-sided. Normal, occlusion, emissive and metallic-roughness maps are not kept.
`material_from_trimesh` reads it from what trimesh loads of a glTF/GLB primitive;
`material_from_mtl` from an OBJ's MTL file (``Kd``, ``d``/``Tr`` and the ``map_Kd``
image of the first material the OBJ uses). Texture images are decoded with Pillow, at
most `MAX_TEXTURE_PIXELS`, and kept as PNG.
"""

from __future__ import annotations

import io
import re
from dataclasses import dataclass

import numpy as np

from retarget.errors import RetargetError

ALPHA_MODES = ("OPAQUE", "MASK", "BLEND")
MAX_TEXTURE_PIXELS = 8192 * 8192
"""Most pixels a texture image may have (a scan's 8K texture); larger ones are refused
before they are decoded."""
_MAP_OPTIONS = {"-blendu": 1, "-blendv": 1, "-bm": 1, "-boost": 1, "-cc": 1, "-clamp": 1,
                "-imfchan": 1, "-mm": 2, "-o": 3, "-s": 3, "-t": 3, "-texres": 1}
"""MTL map statement options and how many values each takes at most (-o, -s, -t take
one to three)."""


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


def texture_png(data: bytes, what: str) -> bytes:
    """A texture image (PNG, JPEG, or another format Pillow reads) as PNG bytes; refused
    with a `RetargetError` naming `what` when it is not an image or has more than
    `MAX_TEXTURE_PIXELS` pixels (checked from its header, before decoding)."""
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(io.BytesIO(data)) as image:
            width, height = image.size
            if width * height > MAX_TEXTURE_PIXELS:
                raise RetargetError(f"{what} is {width}x{height} pixels; a texture may have at "
                                    f"most {MAX_TEXTURE_PIXELS:,} (8192x8192)")
            image.load()
            converted = image.convert("RGBA" if "A" in image.getbands() else "RGB")
    except (UnidentifiedImageError, OSError, ValueError, Image.DecompressionBombError) as exc:
        raise RetargetError(f"{what} is not an image that can be read: {exc}") from None
    out = io.BytesIO()
    converted.save(out, format="PNG")
    return out.getvalue()


def material_from_mtl(obj_text: str, read) -> Material | None:
    """The `Material` of an OBJ (its text) from its MTL files, or None without one.

    read : callable(name) -> bytes or None, the bytes of a file the OBJ or MTL names
        (its base name, any folders stripped), None when it is not there.

    The material is the first one a ``usemtl`` line names (else the first defined):
    ``Kd`` is the base colour, ``d`` (or 1 - ``Tr``) its alpha (BLEND below 1), and the
    ``map_Kd`` image its texture. A missing MTL gives None; a missing or unreadable
    image is refused, naming it.
    """
    libraries = re.findall(r"^[ \t]*mtllib[ \t]+([^\r\n]+)", obj_text, re.MULTILINE)
    used = re.search(r"^[ \t]*usemtl[ \t]+([^\r\n]+)", obj_text, re.MULTILINE)
    wanted = used.group(1).strip() if used else None
    materials: dict[str, dict[str, str]] = {}
    order: list[str] = []
    for library in libraries:
        data = read(_base_name(library))
        if data is None:
            continue
        current = None
        for line in data.decode("utf-8", errors="replace").splitlines():
            key, _, value = line.strip().partition(" ")
            if key == "newmtl":
                current = value.strip()
                materials[current] = {}
                order.append(current)
            elif current is not None and key in ("Kd", "d", "Tr", "map_Kd"):
                materials[current][key] = value.strip()
    if not order:
        return None
    name = wanted if wanted in materials else order[0]
    values = materials[name]
    try:
        color = [float(v) for v in values.get("Kd", "1 1 1").split()[:3]]
        alpha = float(values["d"]) if "d" in values else 1.0 - float(values.get("Tr", "0"))
    except ValueError:
        raise RetargetError(f"material {name!r}: Kd, d or Tr is not a number") from None
    color = [min(max(c, 0.0), 1.0) for c in (color + [1.0] * 3)[:3]]
    alpha = min(max(alpha, 0.0), 1.0)
    texture = None
    if "map_Kd" in values:
        image = _map_file(values["map_Kd"])
        data = read(image)
        if data is None:
            raise RetargetError(f"material {name!r} uses the texture image {image!r}, which was "
                                "not given: upload it with the OBJ and its MTL")
        texture = texture_png(data, f"texture image {image!r}")
    return Material(name=name, base_color=(*color, alpha), metallic=0.0, roughness=1.0,
                    alpha_mode="BLEND" if alpha < 1.0 else "OPAQUE",
                    base_color_texture=texture)


def _map_file(statement: str) -> str:
    """The file name of an MTL map statement, its options (``-s 1 1 1``...) skipped."""
    tokens = statement.split()
    i = 0
    while i < len(tokens) and tokens[i] in _MAP_OPTIONS:
        most = _MAP_OPTIONS[tokens[i]]
        i += 1
        taken = 0
        while i < len(tokens) - 1 and taken < most and _is_option_value(tokens[i]):
            i += 1
            taken += 1
    return _base_name(" ".join(tokens[i:]))


def _is_option_value(token: str) -> bool:
    try:
        float(token)
        return True
    except ValueError:
        return token in ("on", "off") or len(token) == 1


def _base_name(name: str) -> str:
    return name.strip().strip('"').replace("\\", "/").rsplit("/", 1)[-1]
