"""The documentation: the site builds offline with ``mkdocs build --strict`` (a broken
link, a missing page or a generated page that fails is an error), the generated reference holds
every command, option, configuration key, HTTP route and ``rig.json`` key of the code, the
validation pages carry their stamp, the README stays short and its links resolve, and the numpydoc
Examples of the numerics' public entry points run."""

from __future__ import annotations

import argparse
import doctest
import importlib
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

import docs_reference  # noqa: E402  (the mkdocs hook: the generated pages)


@pytest.mark.timeout(600)
def test_the_site_builds_offline_and_strict(tmp_path):
    out = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(tmp_path / "site")],
                         cwd=ROOT, capture_output=True, text=True, env={**os.environ, "NO_MKDOCS_2_WARNING": "1"}, timeout=540)
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-3000:]
    assert "WARNING" not in out.stderr, out.stderr[-3000:]
    site = tmp_path / "site"
    for page in ("index.html", "getting-started/index.html", "reference/configuration/index.html", "reference/cli/index.html",
                 "reference/http-api/index.html", "reference/rig/index.html", "validation/index.html"):
        assert (site / page).exists(), page
    # offline: no web fonts and no scripts or styles from another host in any page
    for html in site.rglob("*.html"):
        text = html.read_text()
        assert "fonts.googleapis" not in text and "fonts.gstatic" not in text, html
        assert not re.search(r"<(script|link)[^>]+(src|href)=\"https?://", text), html


def _options(parser: argparse.ArgumentParser, name: str = "shm"):
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub_name, sub in action.choices.items():
                yield f"{name} {sub_name}", None
                yield from _options(sub, f"{name} {sub_name}")
        elif not isinstance(action, argparse._HelpAction):
            for flag in action.option_strings:
                yield name, flag


def test_the_cli_reference_lists_every_command_and_option():
    from shm_service.cli import build_parser

    page = docs_reference.cli_page()
    seen = 0
    for command, flag in _options(build_parser()):
        if flag is None:
            assert f"`{command}`" in page, command
        else:
            section = page.split(f"`{command}`", 1)[1]
            assert f"`{flag}`" in section, (command, flag)
        seen += 1
    assert seen > 100


def _keys(model):
    """Every key of ``model`` and its sub-models: (name, the model it is a section of, or None)."""
    for name, field in model.model_fields.items():
        sub = docs_reference._submodel(field.annotation)
        yield name, sub
        if sub is not None:
            yield from _keys(sub)


def test_the_configuration_reference_lists_every_key_with_its_default():
    from shm_service.service import ServiceSettings

    page = docs_reference.configuration_page()
    keys = list(_keys(ServiceSettings))
    assert len(keys) > 80
    for key, _section in keys:
        assert f"`{key}`" in page or f"`[{key}]`" in page or f"`[[{key}]]`" in page, key
    # a default as the model has it: the API port, the rest calibration
    assert re.search(r"\| `port` \| int \| `8600` \|", page)
    assert re.search(r"\| `calibration_s` \| float \| `60.0` \|", page)


def test_the_http_reference_lists_every_route_and_types_the_ingest_payloads():
    import contract
    from shm_service.service import create_app

    page = docs_reference.http_page()
    doc = create_app(object()).openapi()
    for path, methods in doc["paths"].items():
        for method in methods:
            assert f"{method.upper()} `{path}`" in page, (method, path)
    for name in doc["components"]["schemas"]:
        assert f"### {name}" in page, name
    # the OpenAPI document itself types each ingest message's payload by its topic
    items = doc["paths"]["/api/ingest"]["post"]["requestBody"]["content"]["application/json"]["schema"]["properties"][
        "messages"]["items"]
    typed = {m["title"]: m["properties"]["payload"] for m in items["oneOf"]}
    assert set(typed) == {"shm.Imu message", "shm.Distance message", "shm.Strain message", "shm.Temperature message"}
    assert typed["shm.Imu message"]["required"] == ["accel", "gyro"]
    for title, schema in contract.SCHEMAS.items():
        assert f"### {title}" in page, title
        for field in schema["properties"]:
            assert f"`{field}`" in page.split(f"### {title}", 1)[1], (title, field)


def test_the_rig_reference_lists_every_rig_json_key():
    import contract

    page = docs_reference.rig_page()
    for key, _ in _keys(contract.RigDescription):
        assert f"`{key}`" in page, key


def test_the_rig_reference_gives_every_key_and_section_shape_a_meaning():
    import contract

    page = docs_reference.rig_page()
    rows = [line for line in page.splitlines() if line.startswith("| `")]
    assert rows and all(not line.rstrip().endswith("|  |") for line in rows), [r for r in rows if r.rstrip().endswith("|  |")]
    for needed in ('`shape = "tube"`', '`shape = "table"`', '`shape = "rectangle"`', "| `beam` |", "| `fatigue` |", "`simulator`",
                   "`sensors[].axes`"):
        assert needed in page, needed
    assert set(contract.EXTENSION_KEYS) <= {k for k in contract.EXTENSION_KEYS if f"`{k}`" in page}


def test_the_channel_map_reference_lists_every_key_with_its_meaning():
    from shm_service.formats.daq_import import ChannelMap, ClockMap, ColumnMap

    page = docs_reference.channel_map_page()
    for model in (ClockMap, ColumnMap):
        for name, field in model.model_fields.items():
            assert f"| `{name}` |" in page and field.description, (model.__name__, name)
    for section in ChannelMap.model_fields:
        assert f"[{section}" in page, section


def test_the_reference_pages_are_in_the_checkout_as_the_code_makes_them():
    index = (ROOT / "docs" / "reference" / "index.md").read_text()
    for link in re.findall(r"\]\(([^)#]+\.md)", index):
        assert (ROOT / "docs" / "reference" / link).exists(), link
    stale = docs_reference.stale_reference_pages()
    assert not stale, f"{stale} differ from the code: run python docs_reference.py --reference"


def test_a_validation_page_is_stamped_or_says_it_was_not_measured(tmp_path, monkeypatch):
    import benchmarks._pages as pages

    monkeypatch.setattr(pages, "RESULTS", tmp_path)
    assert "Not yet measured by `make bench`" in docs_reference._validation_page("bench_oma")
    meta = pages.stamp("python -m benchmarks.bench_oma")
    pages.write_result("bench_oma", "bench_oma: a title", meta, "f1 = 1.000 Hz\n", 1.0)
    page = docs_reference._validation_page("bench_oma")
    for key in ("date", "commit", "machine", "load", "command"):
        assert re.search(rf"^\| {key} \| .+ \|$", page, re.M), key
    assert f"{os.cpu_count()} cores" in page and "`python -m benchmarks.bench_oma`" in page and "f1 = 1.000 Hz" in page
    index = docs_reference.validation_index()  # validation/summary.md
    assert "| [bench_oma](bench_oma.md) |" in index and meta["date"] in index


def test_every_benchmark_has_a_validation_page_in_the_nav():
    from benchmarks.__main__ import MODULES

    nav = (ROOT / "mkdocs.yml").read_text()
    overview = (ROOT / "docs" / "validation" / "index.md").read_text()
    for name in MODULES:
        assert f"validation/{name}.md" in nav, name
        assert f"]({name}.md)" in overview, name


def test_the_readme_is_short_and_its_links_resolve():
    text = (ROOT / "README.md").read_text()
    assert len(text.splitlines()) <= 200
    links = re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", text)
    local = [link for link in links if not re.match(r"[a-z]+://", link)]
    assert len(local) > 10
    for link in local:
        assert (ROOT / link).exists(), link
    for needed in ("make demo", "make test", "LICENSE", "CITATION.cff", "Kohl", "Wagner"):
        assert needed in text, needed
    # the table of the commands has every command of the parser
    from shm_service.cli import build_parser

    for command, flag in _options(build_parser()):
        if flag is None and command.count(" ") == 1:
            assert f"| `{command}" in text, f"README's command table lacks {command}"


def _modules_with_examples() -> tuple[str, ...]:
    """Every module of the packages whose docstrings hold an example (keep them small and fast)."""
    names = []
    for package in ("contract", "estimator", "analytics", "shm_service", "web"):
        for path in sorted((ROOT / package).rglob("*.py")):
            if ">>> " in path.read_text(encoding="utf-8"):
                parts = path.relative_to(ROOT).with_suffix("").parts
                names.append(".".join(parts[:-1] if parts[-1] == "__init__" else parts))
    return tuple(names)


#: Every docstring example of the project runs here (but those marked +SKIP: they need a model and data).
DOCTEST_MODULES = _modules_with_examples()


@pytest.mark.parametrize("name", DOCTEST_MODULES)
def test_docstring_examples_run(name):
    module = importlib.import_module(name)
    flags = doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE
    finder = doctest.DocTestFinder(exclude_empty=True)
    runner = doctest.DocTestRunner(optionflags=flags)
    tests = [t for t in finder.find(module, name) if t.examples]
    assert tests, f"{name} has no docstring examples"
    for test in tests:
        runner.run(test)
    result = runner.summarize(verbose=False)
    assert result.failed == 0, f"{result.failed} of {result.attempted} examples failed in {name}"
