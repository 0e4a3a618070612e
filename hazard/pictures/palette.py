"""Colours shared by the plan view, the elevation view and the 3-D renders, so that a
legend means the same thing in every picture. The lobes, mirror beams and observers use
Okabe & Ito's colour-blind-safe set (Okabe and Ito, "Color Universal Design", 2008); the
danger zone, the aim line and the hazardous observers keep the red a range map uses."""

STATIC = "#0072B2"  # static keep-out lobe (blue)
DYNAMIC = "#E69F00"  # dynamic keep-out lobe (orange)
MIRROR = "#CC79A7"  # mirror (specular) beams to their NOHD (reddish purple)
ZONE = "#e41a1c"  # laser surface danger zone, the laser beam
AIM = "#99000d"  # the aim line past the targets (dark red)
HAZARDOUS = "#e41a1c"  # observers at or above the MPE (drawn large, black-edged)
SAFE = "#009E73"  # observers below the MPE (bluish green)
AIDED = "#984ea3"  # danger zones through optical aids
FOOTPRINT = "#a50f15"  # hazardous ground at eye height (every spot summed, occlusion traced)
TARGET = "#000000"  # targets (white-filled squares in the 2-D views)
DIFFUSE = "#56B4E9"  # a target's longest diffuse NOHD as a circle (sky blue)
RINGS = "#9a9a9a"  # range rings
GROUND = "#cfe3c3"  # ground / terrain
OCCLUDER = "#8c6d31"  # occluders in 3-D (outlined grey in 2-D)


def rgb(hex_colour: str) -> tuple:
    """(r, g, b) in 0-255 of ``#rrggbb``."""
    h = hex_colour.lstrip("#")
    return tuple(int(h[i:i + 2], 16) for i in (0, 2, 4))
