#!/usr/bin/env python3
"""Draw one step of a bag's 3-D scene headless, as Foxglove's 3-D panel shows it (docs/foxglove_scene.png).

    python tools/render_scene.py BAG [--step K|auto] [--out docs/foxglove_scene.png]

Reads the bag with the independent ``mcap`` + ``mcap-ros2-support`` reader (every split) and draws, in a
perspective view with matplotlib's 3-D axes, the markers of ``/avp/viz/scene`` (triangle lists, line strips and
lists, cubes, cylinders: the marker types the scene node uses, with their colours and poses) with the lot of
``/avp/viz/lot`` and the latest spot fill of ``/avp/viz/spots`` at that step, the ray scan of
``/avp/debug/scan`` placed by ``/tf`` (odom -> base_link) and the frame axes of ``map`` and ``base_link``.
``--step auto``: a step whose scene has predictions and a plan and, among those, the most layers and the longest
predicted trajectories.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np


def read(bag: Path) -> tuple[dict[int, object], dict[int, object], dict[int, object]]:
    """{step: scene}, {step: scan}, {step: ego transform} keyed by the header stamp (step = stamp / 0.1 s)."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    def step(stamp) -> int:
        return round((stamp.sec * 1_000_000_000 + stamp.nanosec) / 100_000_000)

    scenes, scans, tfs, static, fills = {}, {}, {}, [], {}
    for f in sorted(Path(bag).glob("*.mcap")):
        with open(f, "rb") as fh:
            for _s, ch, _m, dec in make_reader(fh, decoder_factories=[DecoderFactory()]).iter_decoded_messages(
                    topics=["/avp/viz/scene", "/avp/viz/lot", "/avp/viz/spots", "/avp/debug/scan", "/tf"]):
                if ch.topic == "/avp/viz/lot":
                    static = list(dec.markers)
                elif ch.topic == "/avp/viz/spots":
                    fills[step(dec.markers[0].header.stamp)] = list(dec.markers)
                elif ch.topic == "/avp/viz/scene":
                    stamped = [m for m in dec.markers if m.ns]
                    if stamped:
                        scenes[step(stamped[0].header.stamp)] = dec
                elif ch.topic == "/avp/debug/scan":
                    scans[step(dec.header.stamp)] = dec
                else:
                    for t in dec.transforms:
                        if t.child_frame_id == "base_link":
                            tfs[step(t.header.stamp)] = t
    for k, sc in scenes.items():  # what a viewer shows at step k: the lot, the latest spot fill, the step's scene
        fill = fills[max((s for s in fills if s <= k), default=min(fills))] if fills else []
        sc.markers = [*sc.markers[:1], *static, *fill, *sc.markers[1:]]
    return scenes, scans, tfs


def _rot(q) -> np.ndarray:
    x, y, z, w = q.x, q.y, q.z, q.w
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def _rgba(c) -> tuple[float, float, float, float]:
    return (c.r, c.g, c.b, c.a)


def _pts(m) -> np.ndarray:
    return np.array([[p.x, p.y, p.z] for p in m.points]).reshape(-1, 3)


def _box_faces(m) -> list[np.ndarray]:
    sx, sy, sz = m.scale.x / 2, m.scale.y / 2, m.scale.z / 2
    c = np.array([[i * sx, j * sy, k * sz] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)])
    c = c @ _rot(m.pose.orientation).T + (m.pose.position.x, m.pose.position.y, m.pose.position.z)
    idx = [(0, 1, 3, 2), (4, 5, 7, 6), (0, 1, 5, 4), (2, 3, 7, 6), (0, 2, 6, 4), (1, 3, 7, 5)]
    return [c[list(f)] for f in idx]


def _cylinder_faces(m, n: int = 12) -> list[np.ndarray]:
    a = np.linspace(0, 2 * math.pi, n + 1)
    r, h = m.scale.x / 2, m.scale.z
    x0, y0 = m.pose.position.x, m.pose.position.y
    ring = np.c_[x0 + r * np.cos(a), y0 + r * np.sin(a)]
    return [np.array([[*ring[i], 0], [*ring[i + 1], 0], [*ring[i + 1], h], [*ring[i], h]]) for i in range(n)]


def draw(scene, scan, ego_tf, out: Path, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from mpl_toolkits.mplot3d.art3d import Line3DCollection, Poly3DCollection
    from visualization_msgs.msg import Marker

    fig = plt.figure(figsize=(12, 8), dpi=110, facecolor="#1b1d22")
    ax = fig.add_subplot(projection="3d", facecolor="#1b1d22")
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    for m in scene.markers:
        if m.action != Marker.ADD:
            continue
        if m.type == Marker.TRIANGLE_LIST:
            tri = _pts(m).reshape(-1, 3, 3)
            colors = [_rgba(m.colors[3 * i]) for i in range(len(tri))] if m.colors else _rgba(m.color)
            ax.add_collection3d(Poly3DCollection(tri, facecolors=colors, edgecolors="none"))
            pts = _pts(m)
        elif m.type in (Marker.LINE_STRIP, Marker.LINE_LIST):
            pts = _pts(m)
            segs = np.stack([pts[:-1], pts[1:]], 1) if m.type == Marker.LINE_STRIP else pts.reshape(-1, 2, 3)
            ax.add_collection3d(Line3DCollection(segs, colors=[_rgba(m.color)], linewidths=max(0.6, 6 * m.scale.x)))
        elif m.type in (Marker.CUBE, Marker.CYLINDER):
            faces = _box_faces(m) if m.type == Marker.CUBE else _cylinder_faces(m)
            ax.add_collection3d(Poly3DCollection(faces, facecolors=[_rgba(m.color)], edgecolors=(0, 0, 0, 0.4),
                                                 linewidths=0.3))
            pts = np.vstack(faces)
        else:
            continue
        if len(pts):
            lo, hi = np.minimum(lo, pts.min(0)), np.maximum(hi, pts.max(0))
    if scan is not None and ego_tf is not None:
        r = np.asarray(scan.ranges, dtype=float)
        a = scan.angle_min + scan.angle_increment * np.arange(len(r))
        local = np.c_[r * np.cos(a), r * np.sin(a), np.full(len(r), 0.5)]
        world = local @ _rot(ego_tf.transform.rotation).T + (ego_tf.transform.translation.x,
                                                             ego_tf.transform.translation.y, 0.0)
        ax.scatter(world[:, 0], world[:, 1], world[:, 2], s=2, c="#ff9a00", depthshade=False)
    for origin, rot, label in (((0, 0, 0), np.eye(3), "map"),) + (
            (((ego_tf.transform.translation.x, ego_tf.transform.translation.y, 1.6),
              _rot(ego_tf.transform.rotation), "base_link"),) if ego_tf is not None else ()):
        for axis, col in zip(rot.T, ("#ff3030", "#30ff30", "#3080ff"), strict=True):
            e = np.asarray(origin) + 3 * axis
            ax.plot(*zip(origin, e, strict=True), color=col, lw=2)
        ax.text(*origin, f" {label}", color="white", fontsize=8)
    span = (hi - lo).max()
    mid = (hi + lo) / 2
    ax.set_xlim(mid[0] - span / 2, mid[0] + span / 2)
    ax.set_ylim(mid[1] - span / 2, mid[1] + span / 2)
    ax.set_zlim(0, span / 4)
    ax.set_box_aspect((1, 1, 0.25))
    ax.view_init(elev=48, azim=-70)
    ax.set_axis_off()
    ax.set_title(title, color="white", fontsize=10)
    fig.subplots_adjust(0, 0, 1, 0.95)
    fig.savefig(out, facecolor=fig.get_facecolor())
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("bag")
    p.add_argument("--step", default="auto")
    p.add_argument("--out", default="docs/foxglove_scene.png")
    args = p.parse_args(argv)
    scenes, scans, tfs = read(Path(args.bag))
    if not scenes:
        print(f"{args.bag}: no /avp/viz/scene messages (recorded without the scene node?)", file=sys.stderr)
        return 2
    if args.step == "auto":
        def score(s: int) -> tuple:
            ns = {m.ns for m in scenes[s].markers}
            pred = sum(float(np.linalg.norm(np.diff(_pts(m), axis=0), axis=1).sum())
                       for m in scenes[s].markers if m.ns == "predictions")
            return "predictions" in ns and "plan" in ns, len(ns), round(pred), -s

        k = max(scenes, key=score)
    else:
        k = int(args.step)
    layers = sorted({m.ns for m in scenes[k].markers if m.ns})
    draw(scenes[k], scans.get(k), tfs.get(k), Path(args.out),
         f"{Path(args.bag).name}, step {k} (t = {k / 10:.1f} s): {', '.join(layers)}")
    print(f"{args.out}: step {k}, layers {layers}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
