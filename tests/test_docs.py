"""The documentation cannot drift: the scenario reference is what the generator makes from the
scenario keys, and every relative link in README.md and docs/*.md resolves."""

import importlib.util
import re
from pathlib import Path

from conftest import ROOT

DOCS = ROOT / "docs"
PAGES = [ROOT / "README.md", *sorted(DOCS.glob("*.md"))]
#: [text](target) and ![alt](target), the target up to a space or the closing parenthesis.
LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")
#: Fenced code blocks, whose lines are not headings; with inline code, whose brackets are not links.
FENCED = re.compile(r"```.*?```", re.S)
CODE = re.compile(r"```.*?```|`[^`\n]*`", re.S)


def generator():
    spec = importlib.util.spec_from_file_location("docs_generate", DOCS / "generate.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def anchors(page: Path) -> set[str]:
    """The anchors of a page's headings, as GitHub makes them (duplicates numbered)."""
    seen: dict[str, int] = {}
    out = set()
    for line in FENCED.sub("", page.read_text()).splitlines():
        m = re.match(r"#{1,6}\s+(.*)", line)
        if not m:
            continue
        slug = re.sub(r"[^\w\- ]", "", m.group(1).strip().lower()).replace(" ", "-")
        n = seen.get(slug, 0)
        seen[slug] = n + 1
        out.add(slug if n == 0 else f"{slug}-{n}")
    return out


def links(page: Path) -> list[str]:
    text = CODE.sub("", page.read_text())
    text = re.sub(r"<!--.*?-->", "", text, flags=re.S)
    return [m.group(1) for m in LINK.finditer(text)]


def test_scenario_reference_is_generated_from_the_scenario_keys():
    """docs/scenarios.md is exactly what `docs/generate.py pages` makes from the current keys."""
    expected = generator().scenarios_page()
    assert (DOCS / "scenarios.md").read_text() == expected, (
        "docs/scenarios.md is out of date: run `python docs/generate.py pages`")


def test_every_relative_link_resolves():
    """Every relative link in README.md and docs/*.md names an existing file (and heading)."""
    broken = []
    for page in PAGES:
        for target in links(page):
            if re.match(r"[a-z][a-z0-9+.-]*:", target):  # http:, https:, mailto:
                continue
            path, _, anchor = target.partition("#")
            dest = (page.parent / path).resolve() if path else page
            if not dest.exists():
                broken.append(f"{page.relative_to(ROOT)}: {target}: no such file")
            elif anchor and dest.suffix == ".md" and anchor not in anchors(dest):
                broken.append(f"{page.relative_to(ROOT)}: {target}: no such heading")
    assert not broken, "\n".join(broken)


def test_the_pages_link_to_something():
    """The link check sees the README's links into docs/ (it is not vacuous)."""
    targets = links(ROOT / "README.md")
    assert "docs/usage.md" in targets and "docs/images/replay.png" in targets


#: Counts the README spells out, as words.
WORDS = {w: n for n, w in enumerate(("zero one two three four five six seven eight nine ten eleven twelve thirteen "
                                     "fourteen fifteen").split())}


def test_the_readmes_counts_are_the_trees():
    """The number of shipped configs and of examples the README gives is what the tree holds."""
    text = (ROOT / "README.md").read_text()
    configs = re.search(r"(\w+) ship in \[`config/`\]", text)
    examples = re.search(r"\[`examples/`\]\(examples/\) has (\w+) runnable scripts", text)
    assert configs and examples, "the README no longer states its counts where this test reads them"
    assert WORDS[configs.group(1)] == len(list((ROOT / "config").glob("*.yaml")))
    assert WORDS[examples.group(1)] == len(list((ROOT / "examples").glob("*.py")))
