"""Camera images as the vision model receives them: whole views, and crops.

Pillow reads the file, so a file that is not an image fails here with one
line, before any model call.  The bytes sent are the file's own, except for
a photo whose EXIF tag says it is stored rotated or mirrored (phones do
this): it is turned upright and sent as a PNG, so the model and the crops
see the same pixels whether or not the model honours the tag.  A crop is
re-encoded as PNG, losslessly.
"""

from __future__ import annotations

import io
from dataclasses import dataclass
from pathlib import Path
from typing import Final

from PIL import Image, ImageOps, UnidentifiedImageError

from virf.errors import InputError, printable, read_input_bytes
from virf.planner import Attachment

# Well above a phone camera's JPEG, well below what a chat request may carry
# once base64 has grown it by a third.
MAX_IMAGE_BYTES: Final = 20 * 1024 * 1024
MEDIA_TYPES: Final = {
    "PNG": "image/png",
    "JPEG": "image/jpeg",
    "WEBP": "image/webp",
    "GIF": "image/gif",
}
# EXIF's orientation tag; 1 is upright.
ORIENTATION_TAG: Final = 0x0112
# A crop keeps some surroundings: the material of a rim or handle is often
# read from what is around it.
CROP_MARGIN: Final = 0.1
BBOX_UNITS: Final = ("pixels", "normalized", "per-mille")


@dataclass(frozen=True)
class View:
    """One camera image of the scene."""

    name: str
    image: Attachment
    width: int
    height: int

    @property
    def key(self) -> str:
        """What the run log and replay files know this view's calls by: its
        content, so a renamed file replays and an edited one does not."""
        return f"perceive:{self.image.digest[:16]}"


def load_view(path: str | Path) -> View:
    p = Path(path)
    data = read_input_bytes(p, "image", MAX_IMAGE_BYTES)
    try:
        with Image.open(io.BytesIO(data)) as img:
            kind = img.format or ""
            width, height = img.size
            # Decoded in full: a truncated file must fail here, before any
            # request, not when an object is cropped from it.
            img.load()
            if img.getexif().get(ORIENTATION_TAG, 1) != 1:
                upright = ImageOps.exif_transpose(img)
                out = io.BytesIO()
                upright.save(out, format="PNG")
                kind, data = "PNG", out.getvalue()
                width, height = upright.size
    except Image.DecompressionBombError:
        raise InputError(
            f"image {printable(str(p))} would decode to more than "
            f"{Image.MAX_IMAGE_PIXELS or 0:,} pixels; scale it down"
        ) from None
    except (UnidentifiedImageError, OSError, SyntaxError, ValueError):
        raise InputError(
            f"image {printable(str(p))} is not an image Pillow can read; "
            f"use {', '.join(MEDIA_TYPES)}"
        ) from None
    if kind not in MEDIA_TYPES:
        raise InputError(
            f"image {printable(str(p))} is {kind or 'of an unknown format'}, which vision "
            f"models do not take; convert it to {', '.join(MEDIA_TYPES)}"
        )
    return View(p.name, Attachment(p.name, MEDIA_TYPES[kind], data), width, height)


def pixel_box(
    bbox: tuple[float, float, float, float] | None, view: View, units: str
) -> tuple[int, int, int, int] | None:
    """``bbox`` in the image's pixels, clamped to it; None when nothing is left."""
    if bbox is None:
        return None
    x1, y1, x2, y2 = bbox
    scale = {"pixels": (1.0, 1.0), "normalized": (view.width, view.height)}.get(
        units, (view.width / 1000, view.height / 1000)
    )
    # Clamped before rounding: a box of 1e308 scaled up is infinite.
    xs = sorted(min(max(v * scale[0], -1.0), view.width + 1.0) for v in (x1, x2))
    ys = sorted(min(max(v * scale[1], -1.0), view.height + 1.0) for v in (y1, y2))
    left, right, top, bottom = xs[0], xs[1], ys[0], ys[1]
    box = (
        max(0, round(left)),
        max(0, round(top)),
        min(view.width, round(right)),
        min(view.height, round(bottom)),
    )
    return box if box[2] > box[0] and box[3] > box[1] else None


def crop(view: View, box: tuple[int, int, int, int], name: str) -> Attachment:
    """The object's region of ``view`` (with a margin), as a PNG."""
    x1, y1, x2, y2 = box
    mx, my = round((x2 - x1) * CROP_MARGIN), round((y2 - y1) * CROP_MARGIN)
    region = (
        max(0, x1 - mx),
        max(0, y1 - my),
        min(view.width, x2 + mx),
        min(view.height, y2 + my),
    )
    with Image.open(io.BytesIO(view.image.data)) as img:
        part = img.convert("RGB").crop(region)
        out = io.BytesIO()
        part.save(out, format="PNG")
    return Attachment(name, "image/png", out.getvalue())
