"""Top-down drawings of houses with matplotlib: the picture people look at.

Rooms are filled with a colour per type and named; walls are drawn black,
doors as gaps with a marker, furniture as labelled footprints. Trajectories
and sub-targets are drawn on top by the callers (case studies, replay).
"""

from __future__ import annotations

import os

import matplotlib

matplotlib.use("Agg")
import matplotlib.patches as mpatches  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402

from leaps_mj.world import files, houses  # noqa: E402

#: Fill colour per room type (also used for floor materials and scenes).
ROOM_COLORS = {
    "outdoor": (0.78, 0.88, 0.70),
    "kitchen": (0.98, 0.80, 0.55),
    "dining_room": (0.96, 0.66, 0.60),
    "living_room": (0.70, 0.80, 0.96),
    "bathroom": (0.62, 0.90, 0.92),
    "bedroom": (0.82, 0.72, 0.94),
    "office": (0.92, 0.92, 0.62),
    "garage": (0.72, 0.72, 0.72),
    "indoor": (0.95, 0.95, 0.93),
}


def draw_house(ax, house: houses.House, furniture_labels: bool = True, room_labels: bool = True) -> None:
    """Draws ``house`` on a matplotlib axis in world metres (x right, y up)."""
    for r in sorted(house.rooms, key=lambda r: r.type != "outdoor"):
        x0, y0, x1, y1 = r.rect
        ax.add_patch(mpatches.Rectangle((x0, y0), x1 - x0, y1 - y0, color=ROOM_COLORS[r.type], zorder=0))
    for it in house.items:
        for g in it.geoms:
            x, y, _ = g.pos
            hx, hy = (g.size[0], g.size[1]) if g.shape in ("box", "ellipsoid") else (g.size[0], g.size[0])
            patch = (mpatches.Ellipse((x, y), 2 * hx, 2 * hy) if g.shape != "box"
                     else mpatches.Rectangle((x - hx, y - hy), 2 * hx, 2 * hy))
            patch.set(facecolor=g.rgba[:3], edgecolor=(0.2, 0.2, 0.2), linewidth=0.3, alpha=0.85, zorder=1)
            ax.add_patch(patch)
        if furniture_labels and it.footprint is not None and it.room_type != "outdoor":
            fx0, fy0, fx1, fy1 = it.footprint
            ax.text((fx0 + fx1) / 2, (fy0 + fy1) / 2, it.cls.replace("_", " "), fontsize=4,
                    ha="center", va="center", zorder=3, color=(0.1, 0.1, 0.1))
    for w in house.walls:
        x0, y0, x1, y1 = w.rect
        color = {"wall": "black", "fence": (0.45, 0.35, 0.25), "garage_door": (0.85, 0.3, 0.1)}[w.cls]
        ax.add_patch(mpatches.Rectangle((x0, y0), x1 - x0, y1 - y0, color=color, zorder=2))
    for d in house.doors:
        cx, cy = d.center
        ax.plot([cx], [cy], marker="s", markersize=2.5, color=(0.55, 0.3, 0.1), zorder=3)
    if room_labels:
        for r in house.indoor_rooms:
            x0, y0, x1, y1 = r.rect
            ax.text((x0 + x1) / 2, (y0 + y1) / 2 + 0.3, r.name, fontsize=6, weight="bold",
                    ha="center", va="center", zorder=4,
                    bbox=dict(boxstyle="round,pad=0.15", fc="white", ec="none", alpha=0.7))
    x0, y0, x1, y1 = house.lot
    ax.set_xlim(x0 - 0.5, x1 + 0.5)
    ax.set_ylim(y0 - 0.5, y1 + 0.5)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")


def legend_handles():
    """Legend patches, one per room type."""
    return [mpatches.Patch(color=c, label=t.replace("_", " ")) for t, c in ROOM_COLORS.items()]


def save_figure(fig, path: str | os.PathLike, dpi: int = 150) -> None:
    """Saves a figure atomically (temp file in the same folder + rename) and closes it."""
    try:
        files.write_atomic_with(path, lambda tmp: fig.savefig(tmp, dpi=dpi, bbox_inches="tight"))
    finally:
        plt.close(fig)


def preview(house: houses.House, path: str | os.PathLike) -> None:
    """Writes a top-down PNG of ``house``: rooms by type, doors, furniture."""
    fig, ax = plt.subplots(figsize=(8, 7))
    draw_house(ax, house)
    ax.set_title(f"{house.id}  ({len(house.indoor_rooms)} indoor rooms, {len(house.items)} items)")
    ax.legend(handles=legend_handles(), loc="upper left", bbox_to_anchor=(1.01, 1), fontsize=7)
    save_figure(fig, path)
