"""Every HTML page the package writes, audited in headless Chromium (Debian's ``chromium``;
``.ci/run`` installs it) as a reader sees it at a 1280 px window.

:func:`render` loads a copy of the page with an audit script injected (the page itself
carries no test code, so any page, old or new, can be audited), collects what the reader
would see and takes a full-page screenshot beside the page (``NAME.screenshot.png``, an
artefact, not in git).  :func:`failures` names the checks that fail:

- ``images``: every image loads (and the page has at least one);
- ``script errors``: no script error;
- ``overflow``: nothing wider than the window and no horizontal scroll box (a table that
  scrolls sideways hides columns);
- ``nan``: no ``nan`` in the visible text (a missing value is a dash with a footnote);
- ``raw keys``: no table header (column or row) that is a program identifier
  (``nrmse_heldout_rh_pct``) instead of a name;
- ``units``: every header over bare numbers states its unit (``[µm]``) or is declared
  dimensionless by the page builder (``data-unit``);
- ``temp paths``: no temporary folder of the atomic write (``.eap-tmp-``) in the text;
- ``links``: every link leads somewhere (a section of the page, a file beside it).
"""
import html
import json
import os
import re
import shutil
import subprocess
import tempfile
from pathlib import Path

import pytest

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
needs_browser = pytest.mark.skipif(CHROMIUM is None, reason="chromium is not installed (.ci/run installs it)")
WIDTH = 1280
CHECKS = ("images", "script errors", "overflow", "nan", "raw keys", "units", "temp paths", "links")

#: Injected first in <head>: collects script errors, then on load what a reader sees into
#: ``<body data-eap-audit="{json}">``.
_AUDIT_JS = r"""
(function(){var errs=[];window.addEventListener('error',function(e){errs.push(String(e.message||e));});
var NUM=/^[-\u2212+]?(\d+(\.\d*)?|\.\d+)([eE][-+\u2212]?\d+)?$/, KEY=/^[a-z][a-z0-9]*(_[a-z0-9]+)+$/;
var SUFFIX=/_(pct|percent|m|um|mm|s|hz|v|db|deg|per_v|m_per_v|nm)$/i;
function inScroll(el){for(var p=el.parentElement;p&&p!==document.body;p=p.parentElement){
 var o=getComputedStyle(p).overflowX;if(o=='auto'||o=='scroll')return true;}return false;}
function txt(el){return (el.innerText||el.textContent||'').replace(/\s+/g,' ').trim();}
function hasUnit(th){return th.hasAttribute('data-unit')||/\[[^\]]+\]/.test(txt(th));}
function rawKey(t){if(!t)return false;var toks=t.split(/[\s,;:()]+/).filter(function(x){return x;});
 var bracket=/\[[^\]]+\]/.test(t);return toks.some(function(x){x=x.replace(/[^A-Za-z0-9_]/g,'');
 if(!/_/.test(x)||/\./.test(x))return false;return (KEY.test(x)&&!bracket)||SUFFIX.test(x);});}
window.addEventListener('load',function(){
var imgs=[].slice.call(document.images);
var broken=imgs.filter(function(i){return !(i.complete&&i.naturalWidth>0);}).map(function(i){return i.alt||i.src.slice(0,60);});
var de=document.documentElement,vw=de.clientWidth,wide=[],scroll=[];
[].slice.call(document.body.querySelectorAll('*')).forEach(function(el){var r=el.getBoundingClientRect();
 var cs=getComputedStyle(el);
 if(el.scrollWidth>el.clientWidth+1&&(cs.overflowX=='auto'||cs.overflowX=='scroll')&&r.width>0){
   scroll.push(el.tagName+' '+txt(el).slice(0,60)+' ('+el.scrollWidth+' > '+el.clientWidth+' px)');}
 else if(r.right>vw+1&&r.width>0&&!el.closest('details:not([open])')&&!inScroll(el)){wide.push(el.tagName+' '+txt(el).slice(0,40));}});
var raw=[],unitless=[];
[].slice.call(document.querySelectorAll('table')).forEach(function(tb){
 var rows=[].slice.call(tb.rows);if(!rows.length)return;
 var head=rows[0],hc=[].slice.call(head.cells);
 var kv=hc.length==2&&/^quantity$/i.test(txt(hc[0]));
 hc.forEach(function(c){if(c.tagName=='TH'&&rawKey(txt(c)))raw.push(txt(c));});
 var body=rows.slice(1);
 body.forEach(function(r){var c0=r.cells[0];if(!c0)return;
  if(c0.tagName=='TH'||kv){var t=txt(c0);if(rawKey(t))raw.push(t);
   var v=r.cells[1];if(v&&NUM.test(txt(v))&&!hasUnit(c0))unitless.push(t+' = '+txt(v));}});
 if(kv)return;
 hc.forEach(function(th,j){if(th.tagName!='TH'||hasUnit(th))return;var n=0,num=0;
  body.forEach(function(r){var c=r.cells[j];if(!c||c.tagName=='TH')return;var t=txt(c);if(!t||t=='\u2013'||t=='-')return;
   n++;if(NUM.test(t))num++;});
  if(n&&num*2>=n)unitless.push(txt(th)||'(empty header)');});});
var dead=[].slice.call(document.querySelectorAll('a[href^="#"]')).map(function(a){return a.getAttribute('href');})
 .filter(function(h){return h.length>1&&!document.getElementById(decodeURIComponent(h.slice(1)));});
var vis=txt(document.body),nan=[],tmp=[],m,re=/(^|[^A-Za-z])(nan)(?![A-Za-z])/gi;
while((m=re.exec(vis))&&nan.length<10)nan.push(vis.slice(Math.max(0,m.index-40),m.index+45));
re=/\.eap-tmp-/g;while((m=re.exec(vis))&&tmp.length<10)tmp.push(vis.slice(Math.max(0,m.index-60),m.index+40));
document.body.setAttribute('data-eap-audit',JSON.stringify({images:imgs.length,broken:broken,errors:errs,
 too_wide:wide.slice(0,20),scroll_boxes:scroll.slice(0,20),page_width:de.scrollWidth,window_width:vw,
 height:Math.max(de.scrollHeight,document.body.scrollHeight),raw_headers:raw.slice(0,30),
 unitless_headers:unitless.slice(0,30),nan:nan,temp_paths:tmp,dead_links:dead,
 sections:[].slice.call(document.querySelectorAll('h2')).map(function(h){return txt(h);})}));});})();
"""


def _chromium(width: int, height: int) -> list[str]:
    return [CHROMIUM, "--headless=new", "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
            f"--window-size={width},{height}", "--virtual-time-budget=5000"]


def render(page, width: int = WIDTH, screenshot: bool = True):
    """(the audit dict, the page's text) after loading ``page`` in headless Chromium at
    ``width`` px; with ``screenshot`` a full-page PNG ``NAME.screenshot.png`` beside the
    page (its size in the audit dict as ``screenshot``)."""
    page = Path(page)
    source = page.read_text(encoding="utf-8")
    inject = f"<base href='{page.resolve().parent.as_uri()}/'><script>{_AUDIT_JS}</script>"
    audited = re.sub(r"(<head[^>]*>)", lambda m: m.group(1) + inject, source, count=1, flags=re.I)
    if audited == source:
        audited = inject + source
    with tempfile.TemporaryDirectory(prefix="eap-audit-") as tmp:
        copy = Path(tmp) / "page.html"
        copy.write_text(audited, encoding="utf-8")
        dom = subprocess.run(_chromium(width, 900) + ["--dump-dom", copy.as_uri()], capture_output=True,
                             text=True, timeout=180).stdout
        m = re.search(r'data-eap-audit="([^"]*)"', dom)
        assert m, f"{page}: the audit script did not run"
        check = json.loads(html.unescape(m.group(1)))
        if screenshot:
            shot = page.with_name(page.stem + ".screenshot.png")
            height = max(600, min(int(check["height"]) + 20, 30000))
            subprocess.run(_chromium(width, height) + [f"--screenshot={shot}", copy.as_uri()],
                           capture_output=True, timeout=180)
            check["screenshot"] = f"{width}×{height} px" if shot.is_file() else "not written"
    check["width"] = width
    for href in re.findall(r"href=['\"]([^'\"#]+)['\"]", source):   # links to files beside the page
        if not re.match(r"^(https?|data|mailto):", href) and not (page.parent / html.unescape(href)).exists():
            check["dead_links"].append(href)
    log = os.environ.get("EAP_AUDIT_LOG")   # figures for a closing note: one JSON line per audited page
    if log:
        with open(log, "a", encoding="utf-8") as fh:
            fh.write(json.dumps({"page": str(page), "width": width, "screenshot": check.get("screenshot"),
                                 "failures": failures(check)}, ensure_ascii=False) + "\n")
    return check, html.unescape(re.sub(r"<[^>]+>", " ", dom))


def failures(check: dict) -> dict:
    """The failed checks of an audit: {check name: what failed}."""
    out = {}
    if check["images"] < 1 or check["broken"]:
        out["images"] = check["broken"] or "no image on the page"
    if check["errors"]:
        out["script errors"] = check["errors"]
    if check["too_wide"] or check["scroll_boxes"] or check["page_width"] > check["window_width"] + 1:
        out["overflow"] = (check["scroll_boxes"] + check["too_wide"])[:6] or f"page {check['page_width']} px wide"
    for key, name in (("nan", "nan"), ("raw_headers", "raw keys"), ("unitless_headers", "units"),
                      ("temp_paths", "temp paths"), ("dead_links", "links")):
        if check[key]:
            out[name] = check[key][:8]
    return out


def assert_clean(check, page, allow=()):
    """Every check passes (``allow``: names of checks not applied to this page)."""
    bad = {k: v for k, v in failures(check).items() if k not in allow}
    assert not bad, f"{page}: " + "; ".join(f"{k}: {v}" for k, v in bad.items())


if __name__ == "__main__":   # python tests/browser_check.py PAGE.html ...: the audit of each page
    import sys
    for p in sys.argv[1:]:
        c, _ = render(Path(p))
        f = failures(c)
        print(f"{p}: screenshot {c.get('screenshot')}; "
              + ("all checks pass" if not f else "FAIL " + ", ".join(f)))
        for k, v in f.items():
            print(f"    {k}: {v}")
