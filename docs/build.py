"""Build the documentation site strictly and say how long it took and how many pages it has.

    python docs/build.py            # -> docs/_build/html/index.html

Strict: every warning is an error (-W), every cross-reference must resolve (-n), the build
starts from scratch (-E) and runs every tutorial script, whose checks must hold.
Needs the ``docs`` extra: ``pip install -c constraints.txt -e ".[docs]"``.
"""
import json
import subprocess
import sys
import time
from pathlib import Path

DOCS = Path(__file__).resolve().parent
OUT = DOCS / "_build" / "html"


def main() -> int:
    start = time.perf_counter()
    rc = subprocess.call([sys.executable, "-m", "sphinx", "-W", "--keep-going", "-n", "-E", "-q", "-b", "html",
                          str(DOCS), str(OUT)])
    wall = time.perf_counter() - start
    if rc != 0:
        print(f"docs: build FAILED after {wall:.0f} s (warnings are errors)", file=sys.stderr)
        return rc
    pages = sorted(p for p in OUT.rglob("*.html") if not {"_static", "_sources", "_modules"} & set(p.parts)
                   and p.name not in ("genindex.html", "search.html", "py-modindex.html"))
    times = json.loads((OUT / "tutorial-times.json").read_text()) if (OUT / "tutorial-times.json").is_file() else {}
    print(f"docs: built {len(pages)} pages in {wall:.0f} s -> {OUT / 'index.html'}")
    for name, sec in times.items():
        print(f"  tutorial {name}: {sec:.1f} s")
    if times:
        print(f"  tutorials together: {sum(times.values()):.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
