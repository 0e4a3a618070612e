"""Render the keep-out zones of a scene (off-screen): close view, overview, VTK, animation.

Run:  python examples/render_keepout.py [SCENE] [--out DIR]   (default scene: steel_vs_copper)
"""

import argparse
import os
import sys

import hazard
import scenes


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scene", nargs="?", default="steel_vs_copper")
    ap.add_argument("--out", default=os.path.join(os.path.dirname(__file__), "out", "render"))
    ap.add_argument("--frames", type=int, default=20)
    args = ap.parse_args(argv)
    from hazard.pictures import render

    path = scenes.example_path(args.scene) if args.scene in scenes.examples() else args.scene
    res = hazard.analyze(scenes.load(path))
    for k, p in render.keepout(res, args.out, force=True).items():
        if k not in ("png", "layout", "figures"):
            print(f"{k}: {p}")
    if res.states:
        anim = render.animate_lobe(res, args.out, max_frames=args.frames)
        print(f"animation: {anim.get('gif', anim['frames'][0].parent)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
