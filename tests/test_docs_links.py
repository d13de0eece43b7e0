"""Every link of the README and the docs resolves inside the repository (or is an https URL),
and no text a user reads points outside the repository."""
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
#: Folders whose pages the docs build writes (docs/_ext/eap_docs.py); they are not in a clone.
GENERATED = [ROOT / "docs" / "reference" / d for d in ("commands", "api", "devices")]
PAGES = sorted([ROOT / "README.md", ROOT / "CHANGELOG.md", ROOT / "data" / "README.md"]
               + [p for p in (ROOT / "docs").rglob("*.md")
                  if "_build" not in p.parts and not any(g in p.parents for g in GENERATED)])


def _generated_pages() -> set[Path]:
    """The pages the docs build generates: one per command, per API page, per device file."""
    import sys

    from nnmodel.app.cli import build_parser
    from physics.device import available_devices
    sys.path.insert(0, str(ROOT / "docs"))
    from public_api import PAGES as API
    sub = next(a for a in build_parser()._actions if hasattr(a, "choices") and isinstance(a.choices, dict))
    names = {GENERATED[0]: sub.choices, GENERATED[1]: API, GENERATED[2]: available_devices()}
    return {folder / f"{n}.md" for folder, ns in names.items() for n in [*ns, "index"]}


GENERATED_PAGES = _generated_pages()
LINK = re.compile(r"\[[^\]]*\]\(([^)\s]+)\)")
#: Background files of the project's authors that a clone does not have.
OUTSIDE = re.compile(r"\.\./shared|PHYSICS\.md|DATA_FORMAT\.md|DESIGN\.md|/work/")


def _anchors(md: Path) -> set[str]:
    """GitHub/MyST-style anchors of a Markdown file's headings."""
    out = set()
    for line in md.read_text(encoding="utf-8").splitlines():
        m = re.match(r"#+\s+(.*)", line)
        if m:
            text = re.sub(r"[`*]", "", m.group(1)).strip().lower()
            out.add(re.sub(r"[^\w\- ]", "", text).replace(" ", "-"))
    return out


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_links_resolve(page):
    text = page.read_text(encoding="utf-8")
    for target in LINK.findall(text):
        if target.startswith(("http://", "https://")):
            assert target.startswith("https://"), f"{page.name}: {target}: use https"
            continue
        path, _, anchor = target.partition("#")
        dest = (page.parent / path).resolve() if path else page
        if any(g in dest.parents for g in GENERATED):
            assert dest in GENERATED_PAGES, f"{page.relative_to(ROOT)}: link {target}: the docs build writes no such page"
            continue
        assert dest.exists(), f"{page.relative_to(ROOT)}: link {target} points to nothing"
        assert ROOT in dest.parents or dest == ROOT, f"{page.relative_to(ROOT)}: link {target} leaves the repository"
        if anchor and dest.suffix == ".md":
            assert anchor in _anchors(dest), f"{page.relative_to(ROOT)}: no heading #{anchor} in {path or page.name}"


def test_no_text_points_outside_the_repository():
    sources = PAGES + sorted((ROOT / "physics").rglob("*.py")) + sorted((ROOT / "nnmodel" / "commands").rglob("*.py")) \
        + sorted((ROOT / "configs").rglob("*.yaml")) + sorted((ROOT / "examples").rglob("*.py"))
    bad = [f"{p.relative_to(ROOT)}: {m.group(0)}" for p in sources
           for m in [OUTSIDE.search(p.read_text(encoding="utf-8"))] if m]
    assert not bad, bad
