"""``retarget layouts``: the landmark layouts, their point counts and regions; and custom
layouts (a user's own markers, `retarget.custom_layouts`) made and checked as JSON files.

    retarget layouts                                   list the built-in layouts
    retarget layouts new --names a,b,c --regions brows,brows,nose [--sides right,left,center]
        [--mirror b,a,-] [--anchors a,b,c] [--description TEXT] --out L.json
    retarget layouts new --names-from TAKE.c3d --regions ... --out L.json   the names of a
                                                       take's markers, in its order
    retarget layouts new --from dutreve22 --out L.json a built-in layout's spec, to edit
    retarget layouts check L.json                      check a layout file (or a landmarks
                                                       JSON that carries one) and sum it up
"""

from __future__ import annotations

import json
from pathlib import Path

from retarget.custom_layouts import layout_from_spec, load_layout_file, spec_of_names
from retarget.errors import RetargetError
from retarget.layouts import GROUPS, LAYOUTS, REGIONS, SIDES, Layout, get_layout
from retarget.sources.files import read_take

__all__ = ["add_layouts"]


def add_layouts(commands) -> None:
    p = commands.add_parser("layouts", help="list the landmark layouts; make and check custom ones",
                            description="List the landmark layouts, their point counts and "
                            "regions; make a custom layout file for your own markers ('new') or "
                            "check one ('check').")
    p.set_defaults(run=_list_layouts, quiet=True)
    actions = p.add_subparsers(dest="action", metavar="ACTION")
    new = actions.add_parser("new", help="write a custom layout file",
                             description="Write a custom layout (a JSON spec) for your own markers: "
                             "each point's name, region, side and left/right partner.")
    new.add_argument("--names", metavar="A,B,...", help="the points' names, comma-separated "
                     "(letters, digits, underscores: a take's column names must match them)")
    new.add_argument("--names-from", metavar="TAKE", help="the names of a take file's points (csv, "
                     "json, trc, c3d, ...: its markers), in its order, instead of --names")
    new.add_argument("--regions", metavar="R,R,...", help="each point's region, or one for all: "
                     + ", ".join(REGIONS))
    new.add_argument("--sides", metavar="S,S,...", help="each point's side (the subject's), or one "
                     "for all: " + ", ".join(SIDES) + " (default: center)")
    new.add_argument("--mirror", metavar="P,P,...", help="each point's left/right partner's name, "
                     "'-' for none")
    new.add_argument("--anchors", metavar="A,B,...", help="the points that move with the head only "
                     "(at least 3): head motion is removed on them")
    new.add_argument("--description", default="", help="one line on what the points are")
    new.add_argument("--from", dest="from_layout", metavar="NAME|L.json",
                     help="start from a built-in layout or a layout file (instead of --names)")
    new.add_argument("--out", required=True, metavar="L.json", help="the layout file, written here")
    new.set_defaults(run=_new_layout, quiet=True)
    check = actions.add_parser("check", help="check a custom layout file and sum it up",
                               description="Check a custom layout file, or the layout a "
                               "landmarks JSON carries, and print its points by region.")
    check.add_argument("file", metavar="L.json")
    check.set_defaults(run=_check_layout, quiet=True)


def _list_layouts(args) -> int:
    for name, layout in LAYOUTS.items():
        print(f"{name:<12} {layout.n_points:>3} points  {_region_counts(layout)}")
    print(
        f"--mask takes regions ({', '.join(REGIONS)}), groups ({', '.join(GROUPS)}), "
        "point names or feature indices"
    )
    return 0


def _new_layout(args) -> int:
    given = [o for o, v in (("--names", args.names), ("--names-from", args.names_from),
                            ("--from", args.from_layout)) if v is not None]
    if len(given) != 1:
        raise RetargetError("layouts new: give one of --names or --names-from (with --regions), or --from")
    if args.from_layout is not None:
        base = _existing_layout(args.from_layout)
        spec = base.spec()
        if args.description:
            spec["description"] = args.description
    else:
        if args.regions is None:
            raise RetargetError(f"layouts new: {given[0]} needs --regions")
        names = _listed(args.names) if args.names is not None else list(read_take(args.names_from).names)
        spec = spec_of_names(names, _each(args.regions, len(names), "--regions"),
                             _each(args.sides, len(names), "--sides") if args.sides else None,
                             [None if m == "-" else m for m in _each(args.mirror, len(names), "--mirror")]
                             if args.mirror else None, args.description)
        anchors = set(_listed(args.anchors)) if args.anchors else set()
        unknown = sorted(anchors - set(names))
        if unknown:
            raise RetargetError(f"--anchors names points that --names lacks: {', '.join(unknown)}")
        for point in spec["points"]:
            if point["name"] in anchors:
                point["anchor"] = True
    layout = layout_from_spec(spec)
    Path(args.out).write_text(json.dumps(layout.spec(), indent=1) + "\n")
    print(f"{layout.name}: {layout.n_points} points  {_region_counts(layout)}")
    print(f"wrote {args.out}")
    return 0


def _check_layout(args) -> int:
    layout = _existing_layout(args.file)
    pairs = sum(1 for i, j in enumerate(layout.mirror) if i < j)
    anchors = ", ".join(layout.point_names[i] for i in layout.anchors) or "by name"
    print(f"{layout.name}: {layout.n_points} points  {_region_counts(layout)}")
    print(f"{layout.description}; {pairs} left/right pairs; head anchors: {anchors}")
    return 0


def _existing_layout(text: str) -> Layout:
    """A built-in layout by name, or the custom layout in a layout file or landmarks JSON."""
    if text in LAYOUTS:
        return get_layout(text)
    path = Path(text)
    if not path.is_file():
        raise RetargetError(f"{text!r} is neither a built-in layout ({', '.join(LAYOUTS)}) nor a file")
    try:
        data = json.loads(path.read_text()) if path.stat().st_size < (1 << 20) else None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError):
        data = None
    if isinstance(data, dict) and "layout_spec" in data:
        return layout_from_spec(data["layout_spec"])
    return load_layout_file(path)


def _listed(text: str) -> list[str]:
    return [item.strip() for item in text.split(",")]


def _each(text: str, n: int, option: str) -> list[str]:
    """A comma-separated value per point, or one for all of them."""
    values = _listed(text)
    if len(values) == 1:
        return values * n
    if len(values) != n:
        raise RetargetError(f"{option} has {len(values)} values, --names has {n}")
    return values


def _region_counts(layout: Layout) -> str:
    counts = {r: layout.regions.count(r) for r in REGIONS if r in layout.regions}
    return ", ".join(f"{r} {c}" for r, c in counts.items())
