"""README.md and docs/: size, links, the commands they quote, and the generated tables."""

from __future__ import annotations

import importlib.util
import re
import sys
from pathlib import Path

import pytest

from gait_estimator.cli.app import build_parser

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
PAGES = [README, *sorted((ROOT / "docs").glob("*.md"))]
FENCE = re.compile(r"^(```|~~~).*?^\1\s*$", re.M | re.S)
LINK = re.compile(r"!?\[(?:[^\]\[]|\[[^\]]*\])*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")


def _update_docs():
    spec = importlib.util.spec_from_file_location("benchmarks_common", ROOT / "benchmarks" / "common.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules["benchmarks_common"] = module
    spec.loader.exec_module(module)
    return module


def _prose(text: str) -> str:
    """The text outside fenced code blocks and inline code."""
    return re.sub(r"`[^`\n]*`", "", FENCE.sub("", text))


def _slug(heading: str) -> str:
    """GitHub's anchor for a heading: lower case, punctuation dropped, spaces to hyphens."""
    text = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", heading).strip().lower()
    return re.sub(r"[^\w\- ]", "", text).replace(" ", "-")


def _anchors(path: Path) -> set[str]:
    seen: dict[str, int] = {}
    out = set()
    for line in FENCE.sub("", path.read_text(encoding="utf-8")).splitlines():
        m = re.match(r"^#{1,6}\s+(.*?)\s*#*\s*$", line)
        if m:
            slug = _slug(m.group(1))
            out.add(slug if slug not in seen else f"{slug}-{seen[slug]}")
            seen[slug] = seen.get(slug, 0) + 1
    return out


def test_readme_is_a_front_page() -> None:
    size = README.stat().st_size
    assert size <= 15_000, f"README.md is {size} bytes; move detail to docs/"


def test_docs_fit_their_budget() -> None:
    sizes = {p.name: p.stat().st_size for p in (ROOT / "docs").rglob("*.md")}
    assert sum(sizes.values()) <= 100_000, f"docs/ holds {sum(sizes.values())} bytes: {sizes}"


def test_benchmarks_quoted_in_the_docs_exist() -> None:
    bad = []
    for page in PAGES:
        text = page.read_text(encoding="utf-8")
        bad += [f"{page.name}: benchmarks/{s}" for s in re.findall(r"benchmarks/(\w+\.py)", text)
                if not (ROOT / "benchmarks" / s).is_file()]
        bad += [f"{page.name}: experiments/{s}" for s in re.findall(r"experiments/(\S+)", text)]  # the old folder
    assert bad == []


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_relative_links_resolve(page: Path) -> None:
    bad = []
    for target in LINK.findall(_prose(page.read_text(encoding="utf-8"))):
        if re.match(r"^[a-z][a-z0-9+.-]*:", target):  # http:, https:, mailto:
            continue
        path, _, anchor = target.partition("#")
        file = (page.parent / path).resolve() if path else page
        if not file.exists():
            bad.append(f"{target}: no such file")
        elif anchor and file.suffix == ".md" and anchor not in _anchors(file):
            bad.append(f"{target}: no heading with anchor #{anchor} in {file.relative_to(ROOT)}")
    assert bad == []


def test_the_slug_rule_matches_github() -> None:
    assert _slug("`play`: replay into the live graph without `ros2 bag`") == "play-replay-into-the-live-graph-without-ros2-bag"
    assert _slug("1. Confidence: margin, fit quality, `min_confidence`") == "1-confidence-margin-fit-quality-min_confidence"
    assert _slug("`--out-bag`: the estimator outputs as a bag") == "--out-bag-the-estimator-outputs-as-a-bag"


def _makefile_targets() -> set[str]:
    text = (ROOT / "Makefile").read_text(encoding="utf-8")
    return {t for line in re.findall(r"^([\w .-]+):(?!=)", text, re.M) for t in line.split()}


def test_make_commands_quoted_in_the_docs_exist() -> None:
    readme = README.read_text(encoding="utf-8")
    assert "make test" in readme and "make demo" in readme  # the set-up and demo commands
    quoted = {t for page in PAGES for t in re.findall(r"(?:`|^)make ([a-z][\w-]*)", page.read_text(encoding="utf-8"), re.M)}
    assert {"venv", "test", "demo"} <= quoted
    assert quoted - _makefile_targets() == set()
    assert "make test" in (ROOT / ".ci" / "run").read_text(encoding="utf-8")


def _subcommands() -> dict[str, object]:
    parser = build_parser()
    (sub,) = [a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction"]
    return dict(sub.choices)


def test_gait_estimator_commands_quoted_in_the_docs_exist() -> None:
    commands = _subcommands()
    kernels = {a for a in commands["kernels"]._actions if a.__class__.__name__ == "_SubParsersAction"}
    kernel_commands = set(next(iter(kernels)).choices)
    bad = []
    for page in PAGES:
        for sub, nxt in re.findall(r"gait-estimator ([a-z][\w-]*)(?: ([a-z]+))?", page.read_text(encoding="utf-8")):
            if sub not in commands:
                bad.append(f"{page.name}: gait-estimator {sub}")
            elif sub == "kernels" and nxt and nxt not in kernel_commands:
                bad.append(f"{page.name}: gait-estimator kernels {nxt}")
    assert bad == []


@pytest.mark.parametrize("name", sorted(_subcommands()))
def test_every_command_prints_help(name: str) -> None:
    assert "usage:" in _subcommands()[name].format_help()


def test_generated_tables_are_up_to_date() -> None:
    """Every <!-- BEGIN name --> block equals its benchmarks/results/*/tables.md section."""
    update_docs = _update_docs()
    stale = [f"{page.name}: {changed}" for page in update_docs.pages() for changed in update_docs.update(page)[1]]
    assert stale == [], "run: make docs"


def test_update_docs_splices_sections(tmp_path: Path) -> None:
    update_docs = _update_docs()
    (tmp_path / "t").mkdir()
    (tmp_path / "t" / "tables.md").write_text("intro\n\n### Table 1: a\n\n| x |\n|---|\n| 1 |\n\n### Table 10\n\nten\n")
    page = tmp_path / "page.md"
    page.write_text("# P\n<!-- BEGIN t#Table 1 -->\nold\n<!-- END t#Table 1 -->\ntext\n"
                    "<!-- BEGIN t -->\n<!-- END t -->\n<!-- BEGIN missing -->\nkept\n<!-- END missing -->\n")
    text, changed, pending = update_docs.update(page, tmp_path)
    assert changed == ["t#Table 1", "t"] and pending == ["missing"]
    assert "<!-- BEGIN t#Table 1 -->\n| x |\n|---|\n| 1 |\n<!-- END t#Table 1 -->" in text
    assert "<!-- BEGIN t -->\nintro\n\n### Table 1: a" in text and "\nkept\n" in text
    page.write_text(text)
    assert update_docs.update(page, tmp_path)[1] == []
    page.write_text("<!-- BEGIN t#Table 2 -->\n<!-- END t#Table 2 -->\n")
    with pytest.raises(SystemExit, match="Table 2"):
        update_docs.update(page, tmp_path)
    page.write_text("<!-- BEGIN t -->\nno end\n")
    with pytest.raises(SystemExit, match="without its"):
        update_docs.update(page, tmp_path)
