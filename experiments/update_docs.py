#!/usr/bin/env python3
"""Copy the measured tables from experiments/results/**/tables.md into README.md and docs/*.md.

    python experiments/update_docs.py            # rewrite the generated blocks (make docs)
    python experiments/update_docs.py --check    # exit 1 if a block differs from its source

A generated block in a page is delimited by two HTML comments naming its source:

    <!-- BEGIN beyond#Table 2 -->
    ...                      (replaced by the section of experiments/results/beyond/tables.md
    <!-- END beyond#Table 2 -->  whose heading starts with "Table 2")

``TOPIC`` alone takes the whole of ``experiments/results/TOPIC/tables.md``; ``TOPIC#PREFIX`` takes
the body of its first heading (any level) whose text is PREFIX or starts with PREFIX followed by a
non-alphanumeric character, up to the next heading of the same or a higher level, without the
heading itself. A block whose tables.md does not exist yet is left as it is and reported as
pending (its numbers are older measurements); a missing section in an existing file is an error.
"""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "experiments" / "results"
BLOCK = re.compile(r"^<!-- BEGIN (?P<name>[\w./-]+(?:#[^>]*?)?) -->\n(?P<body>.*?)^<!-- END (?P=name) -->$", re.M | re.S)
HEADING = re.compile(r"^(#{1,6})\s+(.*?)\s*$")


def pages(root: Path = ROOT) -> list[Path]:
    """README.md and every Markdown page under docs/."""
    return [root / "README.md", *sorted((root / "docs").rglob("*.md"))]


def source_path(name: str, results: Path = RESULTS) -> Path:
    return results / name.split("#", 1)[0] / "tables.md"


def section(text: str, prefix: str) -> str | None:
    """Body of the first heading whose text starts with ``prefix`` (see module docstring)."""
    lines = text.splitlines()
    for i, line in enumerate(lines):
        m = HEADING.match(line)
        if not m or not m.group(2).startswith(prefix):
            continue
        rest = m.group(2)[len(prefix):]
        if rest and rest[0].isalnum():
            continue
        level = len(m.group(1))
        end = next((j for j in range(i + 1, len(lines))
                    if (h := HEADING.match(lines[j])) and len(h.group(1)) <= level), len(lines))
        return "\n".join(lines[i + 1:end]).strip()
    return None


def generated(name: str, results: Path = RESULTS) -> str | None:
    """The text a block should hold, or None when its source does not exist yet (pending)."""
    path = source_path(name, results)
    if not path.is_file():
        return None
    text = path.read_text(encoding="utf-8")
    if "#" not in name:
        return text.strip()
    body = section(text, name.split("#", 1)[1])
    if body is None:
        raise SystemExit(f"{path}: no heading starting with {name.split('#', 1)[1]!r} (block {name})")
    return body


def update(page: Path, results: Path = RESULTS) -> tuple[str, list[str], list[str]]:
    """(new text, names of blocks that changed, names of pending blocks) for one page."""
    changed: list[str] = []
    pending: list[str] = []

    def splice(m: re.Match[str]) -> str:
        name = m.group("name")
        new = generated(name, results)
        if new is None:
            pending.append(name)
            return m.group(0)
        body = new + "\n"
        if m.group("body").strip() != new:
            changed.append(name)
        return f"<!-- BEGIN {name} -->\n{body}<!-- END {name} -->"

    text = page.read_text(encoding="utf-8")
    if len(re.findall(r"^<!-- BEGIN ", text, re.M)) != len(BLOCK.findall(text)):
        raise SystemExit(f"{page}: a <!-- BEGIN name --> without its <!-- END name --> (or nested blocks)")
    return BLOCK.sub(splice, text), changed, pending


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--check", action="store_true", help="change nothing; exit 1 if a generated block is out of date")
    args = ap.parse_args(argv)
    stale = []
    for page in pages():
        new_text, changed, pending = update(page)
        rel = page.relative_to(ROOT)
        for name in pending:
            print(f"{rel}: {name}: pending ({source_path(name).relative_to(ROOT)} does not exist yet)")
        for name in changed:
            print(f"{rel}: {name}: {'out of date' if args.check else 'updated'}")
        if changed and not args.check:
            page.write_text(new_text, encoding="utf-8")
        stale += [f"{rel}: {n}" for n in changed]
    if args.check and stale:
        print("generated blocks are out of date; run: make docs", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
