"""Rendering a report in headless Chromium for the tests (Debian's ``chromium``; ``.ci/run``
installs it): the page's own self-check (images, script errors, width) and its text."""
import html
import json
import re
import shutil
import subprocess

import pytest

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
needs_browser = pytest.mark.skipif(CHROMIUM is None, reason="chromium is not installed (.ci/run installs it)")
def render(page, width=1100):
    """(the page's self-check dict, its text) after loading ``page`` in headless Chromium."""
    cmd = [CHROMIUM, "--headless=new", "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
           f"--window-size={width},900", "--virtual-time-budget=5000"]
    dom = subprocess.run(cmd + ["--dump-dom", page.resolve().as_uri()], capture_output=True, text=True,
                         timeout=120).stdout
    subprocess.run(cmd + [f"--screenshot={page.with_name(page.stem + '.screenshot.png')}", page.resolve().as_uri()],
                   capture_output=True, timeout=120)
    m = re.search(r'data-eap-check="([^"]*)"', dom)
    assert m, f"{page}: the page's self-check did not run"
    return json.loads(html.unescape(m.group(1))), re.sub(r"<[^>]+>", " ", dom)


def assert_clean(check, page):
    assert check["images"] >= 1 and not check["broken"], (page, check)
    assert not check["errors"], (page, check)
    assert not check["too_wide"], (page, check)


