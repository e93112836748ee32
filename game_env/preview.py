"""Look at a map: ``python -m game_env.preview --map 3 --out map3.png [--video ep.mp4]``.

The picture is an overview of the whole course (course seed ``--seed``); ``--video`` also
records an episode of the scripted racer from a chase camera (the requested format through
imageio; a GIF if that writer is missing, e.g. mp4 without ffmpeg; else a folder of PNGs).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from game_env.maps import MAPS, check_map_id
from game_env.render import RaceRenderer
from game_env.scripted import ScriptedRacer
from game_env.sim import RaceSim


def _save_png(frame: np.ndarray, path: Path) -> None:
    """A 64-colour palette PNG (Pillow, matplotlib's own dependency): a quarter of the bytes of
    full colour for the flat-shaded course, no visible difference."""
    from PIL import Image

    image = Image.fromarray(np.ascontiguousarray(frame[..., :3]).astype(np.uint8), "RGB")
    palette = image.quantize(colors=64, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE)
    palette.save(path, optimize=True)


def overview(map_id: int, seed: int = 0, width: int = 960, height: int = 540) -> np.ndarray:
    """An RGB overview picture of the course of (map_id, seed), racers on the start pad."""
    sim = RaceSim(4)
    sim.load(check_map_id(map_id), seed)
    sim.reset()
    c = sim.course
    zs = [s.z0 for s in c.surfaces] + [s.z1 for s in c.surfaces]
    renderer = RaceRenderer(sim.model, width, height)
    try:
        return renderer.overview(sim.data, c.surfaces[0].x0, c.length, float(np.mean(zs)))
    finally:
        renderer.close()


def record(map_id: int, seed: int, out: Path, steps: int = 1000, width: int = 480, height: int = 320) -> Path:
    """Record the scripted racer's episode; returns the written path."""
    sim = RaceSim(1, max_episode_steps=steps)
    sim.load(check_map_id(map_id), seed)
    sim.reset()
    bot = ScriptedRacer(sim)
    renderer = RaceRenderer(sim.model, width, height)
    frames = []
    for k in range(steps):
        _, _, done, err = sim.step(bot.act()[None])
        if k % 2 == 0:
            sim.sync_visuals()
            frames.append(renderer.chase(sim.data, sim.pos[0]).copy())
        if done[0] or err:
            break
    renderer.close()
    try:
        import imageio.v2 as imageio
    except ImportError:
        imageio = None
    for path in (out, out.with_suffix(".gif")):  # mp4 needs ffmpeg; GIF only Pillow
        if imageio is None:
            break
        try:
            if path.suffix == ".gif":
                imageio.mimsave(path, frames, duration=1000 / 12, loop=0)
            else:
                imageio.mimsave(path, frames, fps=12)
            return path
        except Exception:  # noqa: BLE001 - writer backend missing: try the next format
            path.unlink(missing_ok=True)
    folder = out.with_suffix("")  # last resort: a folder of PNG frames
    folder.mkdir(parents=True, exist_ok=True)
    for k, f in enumerate(frames):
        _save_png(f, folder / f"frame{k:04d}.png")
    return folder


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--map", type=int, required=True, help="map id 0..9")
    parser.add_argument("--seed", type=int, default=0, help="course seed")
    parser.add_argument("--out", type=Path, default=None, help="PNG path (default mapN.png)")
    parser.add_argument("--video", type=Path, default=None, help="also record an episode here")
    args = parser.parse_args(argv)
    map_id = check_map_id(args.map)
    out = args.out or Path(f"map{map_id}.png")
    _save_png(overview(map_id, args.seed), out)
    print(f"map {map_id} ({MAPS[map_id].name}): {out}")
    if args.video is not None:
        print(f"episode: {record(map_id, args.seed, args.video)}")


if __name__ == "__main__":
    main()
