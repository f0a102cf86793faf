"""``retarget layouts``: the landmark layouts, their point counts and regions."""

from __future__ import annotations

from retarget.layouts import GROUPS, LAYOUTS, REGIONS

__all__ = ["add_layouts"]


def add_layouts(commands) -> None:
    p = commands.add_parser("layouts", help="list the landmark layouts and their regions",
                            description="List the landmark layouts, their point counts and "
                            "regions.")
    p.set_defaults(run=_layouts, quiet=True)


def _layouts(args) -> int:
    for name, layout in LAYOUTS.items():
        counts = {r: layout.regions.count(r) for r in REGIONS if r in layout.regions}
        regions = ", ".join(f"{r} {c}" for r, c in counts.items())
        print(f"{name:<12} {layout.n_points:>3} points  {regions}")
    print(
        f"--mask takes regions ({', '.join(REGIONS)}), groups ({', '.join(GROUPS)}), "
        "point names or feature indices"
    )
    return 0
