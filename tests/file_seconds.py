"""The measured cost of each test file, which orders the files for pytest-xdist: a worker
takes one file at a time, so a long file started last leaves the other workers idle while
it runs (xdist's own order, by number of tests, puts the long one-test browser files last).
Longest first (longest processing time first, Graham 1969) ends the run sooner.

``python -m tests.file_seconds DURATIONS.txt`` rewrites ``file_seconds.json`` from the
output of ``pytest --durations=0`` (setup, call and teardown summed per file). Only the
order matters, so a loaded machine's figures do; a file missing from the table (a new
one) counts as the table's median.
"""

from __future__ import annotations

import json
import re
import sys
from collections import Counter
from pathlib import Path

TABLE = Path(__file__).with_name("file_seconds.json")
_LINE = re.compile(r"^([\d.]+)s (?:setup|call|teardown)\s+(\S+?\.py)::", re.M)


def file_seconds() -> dict[str, float]:
    """{path relative to the repository: seconds} from the table; {} when it is missing."""
    try:
        return json.loads(TABLE.read_text())
    except (OSError, ValueError):
        return {}


def longest_first(items, seconds: dict[str, float]) -> None:
    """Sort pytest `items` in place, files by descending `seconds`, keeping each file's own
    order (the sort is stable and a file's items share one key)."""
    if not seconds:
        return
    known = sorted(seconds.values())
    median = known[len(known) // 2]
    items.sort(key=lambda item: -seconds.get(item.nodeid.split("::", 1)[0], median))


def main(path: str) -> None:
    totals: Counter[str] = Counter()
    for match in _LINE.finditer(Path(path).read_text()):
        totals[match[2]] += float(match[1])
    TABLE.write_text(json.dumps({f: round(s, 1) for f, s in sorted(totals.items())}, indent=0) + "\n")
    print(f"{len(totals)} files, {sum(totals.values()):.0f} s in all -> {TABLE}")


if __name__ == "__main__":
    main(sys.argv[1])
