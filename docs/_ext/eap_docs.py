"""Sphinx extension of the eap-model docs.

* Writes the generated reference pages before the sources are read (never committed):
  ``reference/commands/NAME.md`` for every ``eap`` command, from its argparse parser
  (:func:`nnmodel.app.cli.build_parser`), and ``reference/api/PAGE.md`` for every entry of
  ``docs/public_api.py`` (autodoc of the names users import).
* ``{tutorial-output} SCRIPT.py``: runs a tutorial script once per build (a fresh process,
  in the repository root) and shows what it printed; a script that fails — a command that
  errs or a claim it checks that does not hold — fails the build.  Run times are written to
  ``tutorial-times.json`` in the output folder.
"""
from __future__ import annotations

import argparse
import importlib
import json
import os
import subprocess
import sys
import time
from pathlib import Path

from docutils import nodes
from docutils.parsers.rst import Directive
from sphinx.errors import ExtensionError
from sphinx.util import logging

DOCS = Path(__file__).resolve().parents[1]
ROOT = DOCS.parent
log = logging.getLogger(__name__)
TIMES: dict[str, float] = {}


# ------------------------------------------------------------------------- generated pages
def _write(path: Path, text: str) -> None:
    """Write ``text`` only when it changed (Sphinx then re-reads only what changed)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    if not path.is_file() or path.read_text(encoding="utf-8") != text:
        path.write_text(text, encoding="utf-8")


def _md(text: str) -> str:
    """Argparse help as Markdown text: literal characters that Markdown would read as markup escaped."""
    for ch in ("\\", "*", "_", "<", "[", "]", "|"):
        text = text.replace(ch, "\\" + ch)
    return " ".join(text.split())


def _option_entry(action: argparse.Action, parser: argparse.ArgumentParser) -> str | None:
    if action.help == argparse.SUPPRESS:
        return None
    formatter = parser._get_formatter()
    names = formatter._format_action_invocation(action)
    help_text = formatter._expand_help(action) if action.help else ""
    default = action.default
    if default not in (None, False, argparse.SUPPRESS, [], "") and "(default" not in help_text \
            and not action.required and action.option_strings:
        help_text += f" (default: {default})"
    return f"`{names}`\n: {_md(help_text) or '–'}\n"


def command_pages(out: Path) -> list[str]:
    """One Markdown page per ``eap`` command under ``out``; returns the command names."""
    from nnmodel.app.cli import build_parser
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    names = sorted(sub.choices)
    helps = {a.dest: a.help for a in sub._choices_actions}
    for name in names:
        p = sub.choices[name]
        usage = p.format_usage().strip()
        positional = [a for a in p._actions if not a.option_strings]
        optional = [a for a in p._actions if a.option_strings]
        parts = [f"# eap {name}\n", "<!-- generated from the command's argument parser by docs/_ext/eap_docs.py -->\n",
                 _md(p.description or "") + "\n", "```text\n" + usage + "\n```\n"]
        for title, actions in (("Arguments", positional), ("Options", optional)):
            entries = [e for e in (_option_entry(a, p) for a in actions) if e]
            if entries:
                parts.append(f"## {title}\n\n" + "\n".join(entries))
        _write(out / f"{name}.md", "\n".join(parts))
    index = ["# Commands\n", "<!-- generated from nnmodel/app/cli.py's parser by docs/_ext/eap_docs.py -->\n",
             "Every page below is generated from the command's own argument parser, so it says what "
             "`eap COMMAND --help` says.  Options that take a device also take `--param NAME=VALUE`; "
             "those that take `--effects` also take `--effects-path FILE.py`.\n",
             "| command | what it does |\n|---|---|"]
    index += [f"| [`eap {n}`]({n}.md) | {_md(helps.get(n) or '')} |" for n in names]
    index += ["\n```{toctree}\n:hidden:\n\n" + "\n".join(names) + "\n```\n"]
    _write(out / "index.md", "\n".join(index))
    for stale in out.glob("*.md"):
        if stale.stem not in names and stale.stem != "index":
            stale.unlink()
    return names


def _directive(name: str) -> str:
    module, _, attr = name.rpartition(".")
    obj = getattr(importlib.import_module(module), attr)
    if isinstance(obj, type):
        return f"```{{eval-rst}}\n.. autoclass:: {name}\n   :members:\n```\n"
    if callable(obj):
        return f"```{{eval-rst}}\n.. autofunction:: {name}\n```\n"
    return f"```{{eval-rst}}\n.. autodata:: {name}\n   :no-value:\n```\n"


def api_pages(out: Path) -> None:
    """One page per entry of ``docs/public_api.py``."""
    sys.path.insert(0, str(DOCS))
    from public_api import PAGES
    for page, (title, about, names) in PAGES.items():
        body = [f"# `{title}`\n", "<!-- generated from docs/public_api.py by docs/_ext/eap_docs.py -->\n", about + "\n"]
        body += [_directive(n) for n in names]
        _write(out / f"{page}.md", "\n".join(body))
    index = ["# Python API\n", "<!-- generated from docs/public_api.py by docs/_ext/eap_docs.py -->\n",
             "Documented under the names you import.  Every example on these pages is run by the test suite "
             "(`tests/test_docstring_examples.py`).\n", "| module | what it holds |\n|---|---|"]
    index += [f"| [`{t}`]({p}.md) | {a} |" for p, (t, a, _) in PAGES.items()]
    index += ["\n```{toctree}\n:hidden:\n\n" + "\n".join(PAGES) + "\n```\n"]
    _write(out / "index.md", "\n".join(index))


def _cell(text) -> str:
    return _md(str(text)) if text not in (None, "") else "–"


def device_pages(out: Path) -> None:
    """``reference/devices/NAME.md``: every value of each shipped device file with its unit and
    source, read from ``configs/devices/NAME.yaml`` itself."""
    import yaml
    from physics.device import config_dir
    names = []
    for path in sorted((config_dir() / "devices").glob("*.yaml")):
        raw = yaml.safe_load(path.read_text(encoding="utf-8"))
        names.append(path.stem)
        body = [f"# Device `{path.stem}`\n", f"<!-- generated from configs/devices/{path.name} by docs/_ext/eap_docs.py -->\n",
                f"**{_md(raw.get('title', ''))}**  \n{_md(raw.get('reference', ''))}\n",
                f"Default effects: {', '.join(f'`{e}`' for e in raw.get('default_effects', []))}; "
                f"reference humidity {raw.get('reference_rh', {}).get('value', '–')} %.\n"]
        for section, values in raw.items():
            if not isinstance(values, dict) or section in ("reference_rh",):
                continue
            rows = []
            for key, v in values.items():
                if isinstance(v, dict) and "value" in v:
                    rows.append(f"| `{key}` | {_cell(v['value'])} | {_cell(v.get('unit'))} | {_cell(v.get('source'))} |")
                elif isinstance(v, dict):
                    n = max((len(x.get("values", [])) for x in v.values() if isinstance(x, dict)), default=0)
                    rows.append(f"| `{key}` | table of {n} points | – | {_cell(v.get('source'))} |")
            if rows:
                body += [f"## {section}\n", "| name | value | unit | source |\n|---|---|---|---|", *rows, ""]
        if raw.get("notes"):
            body += ["## Notes\n"] + [f"- {_md(n)}" for n in raw["notes"]] + [""]
        _write(out / f"{path.stem}.md", "\n".join(body))
    index = ["# Devices\n", "<!-- generated from configs/devices/ by docs/_ext/eap_docs.py -->\n",
             "The shipped device files, every value with its unit and its source in the thesis.  "
             "`eap effects --device NAME` prints the same values in SI.\n"]
    index += [f"- [`{n}`]({n}.md)" for n in names]
    index += ["\n```{toctree}\n:hidden:\n\n" + "\n".join(names) + "\n```\n"]
    _write(out / "index.md", "\n".join(index))


# ------------------------------------------------------------------------- tutorials
class TutorialOutput(Directive):
    """``{tutorial-output} SCRIPT`` (relative to the page): the script's printed output."""

    required_arguments = 1
    has_content = False

    def run(self):
        env = self.state.document.settings.env
        page_dir = Path(env.doc2path(env.docname)).parent
        script = (page_dir / self.arguments[0]).resolve()
        env.note_dependency(str(script))
        env.note_dependency(str(script.parent / "_tutorial.py"))
        if not script.is_file():
            raise self.error(f"tutorial script {script} not found")
        if os.environ.get("EAP_DOCS_SKIP_TUTORIALS"):       # a quick draft build while writing pages
            log.warning(f"tutorial {script.name} not run (EAP_DOCS_SKIP_TUTORIALS is set)")
            return [nodes.literal_block("(not run)", "(not run)")]
        pythonpath = os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")]))
        start = time.perf_counter()
        proc = subprocess.run([sys.executable, str(script)], cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                              text=True, env={**os.environ, "PYTHONPATH": pythonpath, "PYTHONUNBUFFERED": "1"},
                              timeout=900)
        TIMES[script.name] = round(time.perf_counter() - start, 1)
        text = proc.stdout.strip("\n")
        if proc.returncode != 0:
            raise ExtensionError(f"tutorial {script.name} failed (exit {proc.returncode}):\n{text[-4000:]}")
        log.info(f"tutorial {script.name}: {TIMES[script.name]} s")
        block = nodes.literal_block(text, text)
        block["language"] = "text"
        return [block]


def _write_times(app, exception):
    if exception is None and TIMES:
        (Path(app.outdir) / "tutorial-times.json").write_text(json.dumps(TIMES, indent=1) + "\n", encoding="utf-8")


def setup(app):
    command_pages(DOCS / "reference" / "commands")
    api_pages(DOCS / "reference" / "api")
    device_pages(DOCS / "reference" / "devices")
    app.add_directive("tutorial-output", TutorialOutput)
    app.connect("build-finished", _write_times)
    return {"version": "1", "parallel_read_safe": False, "parallel_write_safe": True}
