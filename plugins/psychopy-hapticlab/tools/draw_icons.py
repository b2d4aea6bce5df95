"""Draw the components' Builder icons (48 and 96 px, Builder's light, dark and classic
themes): a stylus over a surface with a decaying sinusoid (Haptic contact), a stylus with a
check mark (Haptic device check). Run once; the PNGs are committed beside the components.

    .venv/bin/python plugins/psychopy-hapticlab/tools/draw_icons.py
"""

import math
from pathlib import Path

from PIL import Image, ImageDraw

HERE = Path(__file__).resolve().parents[1] / "psychopy_hapticlab" / "components"
THEMES = {"light": ((0, 0, 0, 0), (40, 40, 48, 255), (232, 76, 61, 255)),
          "dark": ((0, 0, 0, 0), (236, 236, 240, 255), (255, 120, 100, 255)),
          "classic": ((149, 149, 149, 255), (20, 20, 24, 255), (200, 40, 30, 255))}


def draw(kind: str, size: int, bg, fg, accent) -> Image.Image:
    s = size / 48
    im = Image.new("RGBA", (size, size), bg)
    d = ImageDraw.Draw(im)
    w = max(1, round(2.5 * s))
    # the stylus: a pen shaft down to its tip
    d.line([(30 * s, 4 * s), (18 * s, 26 * s)], fill=fg, width=round(5 * s))
    d.polygon([(16 * s, 24 * s), (21 * s, 27 * s), (15 * s, 31 * s)], fill=fg)
    if kind == "contact":
        d.line([(4 * s, 33 * s), (44 * s, 33 * s)], fill=fg, width=w)  # the surface
        pts = [(6 * s + i * s, 41 * s - 7 * s * math.exp(-i / 12) * math.sin(i / 2.2))
               for i in range(37)]
        d.line(pts, fill=accent, width=w)  # the decaying sinusoid
    else:
        d.line([(24 * s, 38 * s), (31 * s, 45 * s), (45 * s, 28 * s)], fill=accent,
               width=round(4 * s))
    return im


for kind, stem in (("contact", "hapticContact"), ("check", "hapticCheck")):
    for theme, colours in THEMES.items():
        folder = HERE / kind / theme
        folder.mkdir(parents=True, exist_ok=True)
        draw(kind, 48, *colours).save(folder / f"{stem}.png")
        draw(kind, 96, *colours).save(folder / f"{stem}@2x.png")
    draw(kind, 48, *THEMES["light"]).save(HERE / kind / f"{stem}.png")
