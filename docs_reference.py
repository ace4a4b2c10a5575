"""The documentation's reference pages, generated from the code so they cannot drift.

A MkDocs hook (``mkdocs.yml``: ``hooks: [docs_reference.py]``): at every build it adds these pages
to the site, made from the objects the product itself uses:

- ``reference/configuration.md``: every key of ``shm serve``'s TOML (``ServiceSettings`` and its
  sections, pydantic models) with its type, default and meaning;
- ``reference/cli.md``: every command and option of ``shm`` (``shm_service.cli.build_parser``);
- ``reference/http-api.md``: every route of the HTTP API from its OpenAPI document (FastAPI's, as
  ``/openapi.json`` serves it), with each schema's fields, and the ingest payload of each topic
  typed from the recording contract's JSON schemas;
- ``reference/rig.md``: every ``rig.json`` key (``contract.RigDescription`` and its parts) and the
  recording contract's topics and payloads.

- ``reference/channel-map.md``: the channel map of ``shm import`` (``shm_service.formats.daq_import.ChannelMap``).

The reference pages are also kept in the checkout (``docs/reference/*.md``, so that the links of
``docs/reference/index.md`` resolve without a build); ``python docs_reference.py --reference``
rewrites them from the code, and a test fails while they differ. ``python docs_reference.py
OUT_DIR`` writes every generated page as files (to read them without MkDocs).
"""

from __future__ import annotations

import argparse
import json
import sys
import typing
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))
# mkdocs puts this directory on sys.path only while it loads this hook and restores sys.path after:
# the benchmarks package (not installed) is imported now so that its modules are found at build time
import benchmarks  # noqa: E402,F401

GENERATED = "!!! note \"Generated\"\n    This page is generated from the code at every build of the documentation ({what}); edit the code, not the page.\n\n"


def _cell(text: Any) -> str:
    s = "" if text is None else str(text)
    return s.replace("|", "\\|").replace("\n", " ").strip()


def _type_name(annotation: Any) -> str:
    if annotation is None:
        return "None"
    origin = typing.get_origin(annotation)
    if origin is typing.Literal:
        return " \\| ".join(repr(a).replace("'", '"') for a in typing.get_args(annotation))
    if origin is typing.Annotated:
        return _type_name(typing.get_args(annotation)[0])
    if origin in (typing.Union, getattr(__import__("types"), "UnionType", None)):
        return " \\| ".join(_type_name(a) for a in typing.get_args(annotation))
    if origin in (tuple, list, dict):
        args = typing.get_args(annotation)
        inner = ", ".join(_type_name(a) for a in args if a is not Ellipsis)
        return f"{origin.__name__}[{inner}]" if inner else origin.__name__
    if annotation is type(None):
        return "None"
    return getattr(annotation, "__name__", str(annotation).replace("typing.", ""))


def _default(field: Any) -> str:
    from pydantic_core import PydanticUndefined

    if field.default is PydanticUndefined:
        if field.default_factory is not None:
            try:
                value = field.default_factory()
            except TypeError:
                return "(computed)"
        else:
            return "**required**"
    else:
        value = field.default
    if hasattr(value, "model_dump"):
        return "(section)"
    try:
        return f"`{json.dumps(value, default=str)}`"
    except TypeError:
        return f"`{value!r}`"


def _submodel(annotation: Any) -> Any:
    from pydantic import BaseModel

    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return annotation
    for arg in typing.get_args(annotation):
        found = _submodel(arg)
        if found is not None:
            return found
    return None


def _submodels(annotation: Any) -> list[Any]:
    """Every pydantic model in ``annotation`` (each member of a union such as a section's shapes)."""
    from pydantic import BaseModel

    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return [annotation]
    found: list[Any] = []
    for arg in typing.get_args(annotation):
        found += [m for m in _submodels(arg) if m not in found]
    return found


def _model_table(model: Any, prefix: str = "", *, sections: bool = False) -> tuple[list[str], list[tuple[str, Any]]]:
    """Rows of ``model``'s keys, and its sub-models (name, model) to document apart. ``sections``:
    a key holding a sub-model gets a row too (its type "section"), as every collection key does."""
    rows, subs = [], []
    for name, field in model.model_fields.items():
        models = _submodels(field.annotation)
        collection = typing.get_origin(field.annotation) in (tuple, list, dict) or any(
            typing.get_origin(a) in (tuple, list, dict) for a in typing.get_args(field.annotation))
        if models and not collection:
            subs += [(prefix + name, m) for m in models]
            if sections:
                rows.append(f"| `{prefix}{name}` | section ({' or '.join(m.__name__ for m in models)}) | {_default(field)} | "
                            f"{_cell(field.description)} |")
            continue
        subs += [(prefix + name + "[]", m) for m in models]
        rows.append(f"| `{prefix}{name}` | {_type_name(field.annotation)} | {_default(field)} | {_cell(field.description)} |")
    return rows, subs


def _model_sections(model: Any, title: str, level: int = 2, seen: set | None = None, *, sections: bool = False) -> list[str]:
    seen = set() if seen is None else seen
    rows, subs = _model_table(model, sections=sections)
    out = [f"{'#' * level} {title}", ""]
    doc = (model.__doc__ or "").strip()
    if doc and not doc.startswith("Usage docs"):
        out += [doc.split("\n\n")[0].replace("\n", " "), ""]
    if rows:
        out += ["| key | type | default | meaning |", "| --- | --- | --- | --- |", *rows, ""]
    for name, sub in subs:
        if sub in seen:
            continue
        seen.add(sub)
        shape = sub.model_fields.get("shape")
        variant = typing.get_args(shape.annotation) if shape is not None and typing.get_origin(shape.annotation) is typing.Literal else ()
        head = f"`{name}` with `shape = \"{variant[0]}\"` ({sub.__name__})" if variant else f"`{name}` ({sub.__name__})"
        out += _model_sections(sub, head if not name.startswith("[") else name, level + (level < 4), seen, sections=sections)
    return out


# ---------------------------------------------------------------------------------------- pages
def configuration_page() -> str:
    from shm_service.service._config import ServiceSettings

    out = ["# Configuration reference", "", GENERATED.format(what="from `shm_service.service._config.ServiceSettings`"),
           "`shm serve --config FILE` reads one TOML file; command-line flags override it; "
           "`shm serve --print-config` prints the effective configuration with every key. A key that is not "
           "listed here is an error (the configuration is closed), and each value is checked against its range "
           "when the file is read. Sections are TOML tables (`[estimator]`); `[[structures]]` entries make a fleet.", ""]
    rows, subs = _model_table(ServiceSettings)
    out += ["## Top-level keys", "", "| key | type | default | meaning |", "| --- | --- | --- | --- |", *rows, ""]
    seen: set = {ServiceSettings}
    for name, sub in subs:
        seen.add(sub)
        table = f"[[{name[:-2]}]]" if name.endswith("[]") else f"[{name}]"
        out += _model_sections(sub, f"`{table}`", 2, seen)
    return "\n".join(out) + "\n"


def _walk_parser(parser: argparse.ArgumentParser, name: str, level: int) -> list[str]:
    out = [f"{'#' * min(level, 4)} `{name}`", ""]
    if parser.description:
        out += [parser.description, ""]
    usage = parser.format_usage().replace("usage: ", "").strip()
    out += ["```text", usage, "```", ""]
    rows = []
    subparsers = []
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            helps = {a.dest: a.help for a in action._choices_actions}
            for sub_name, sub in action.choices.items():
                subparsers.append((sub_name, sub, helps.get(sub_name)))
            continue
        if isinstance(action, argparse._HelpAction):
            continue
        flags = ", ".join(f"`{o}`" for o in action.option_strings) or f"`{action.dest}` (positional)"
        if action.metavar and action.option_strings:
            flags += f" {_cell(action.metavar)}"
        choices = f" One of: {', '.join(f'`{c}`' for c in action.choices)}." if action.choices else ""
        default = "" if action.default in (None, False, argparse.SUPPRESS) or action.option_strings == [] else f"`{action.default}`"
        rows.append(f"| {flags} | {_cell(action.help)}{choices} | {default} |")
    if rows:
        out += ["| option | meaning | default |", "| --- | --- | --- |", *rows, ""]
    for sub_name, sub, help_ in subparsers:
        sub_out = _walk_parser(sub, f"{name} {sub_name}", level + 1)
        if help_ and not sub.description:
            sub_out.insert(2, help_ + "\n")
        out += sub_out
    return out


def cli_page() -> str:
    from shm_service.cli import build_parser

    parser = build_parser()
    out = ["# Command-line reference", "", GENERATED.format(what="from `shm_service.cli.build_parser`"),
           "Every command answers `--help`, checks its arguments before it imports the numerics, and refuses a "
           "value out of range naming the valid range (nothing is clamped).", ""]
    commands = []
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            helps = {a.dest: a.help for a in action._choices_actions}
            commands = [(n, helps.get(n, "")) for n in action.choices]
    out += ["| command | what it does |", "| --- | --- |", *[f"| [`shm {n}`](#shm-{n}) | {_cell(h)} |" for n, h in commands], ""]
    out += _walk_parser(parser, "shm", 2)[4:]  # the commands (the top level's usage is in the table)
    return "\n".join(out) + "\n"


def _schema_type(schema: dict[str, Any]) -> str:
    if "$ref" in schema:
        name = schema["$ref"].rsplit("/", 1)[-1]
        return f"[{name}](#{name.lower()})"
    if "anyOf" in schema:
        return " or ".join(_schema_type(s) for s in schema["anyOf"])
    if "oneOf" in schema:
        return "one of: " + ", ".join(s.get("title") or _schema_type(s) for s in schema["oneOf"])
    if "enum" in schema:
        return " \\| ".join(json.dumps(v) for v in schema["enum"])
    if "const" in schema:
        return json.dumps(schema["const"])
    t = schema.get("type", "any")
    if t == "array":
        return f"array of {_schema_type(schema.get('items', {}))}"
    if t == "object" and "additionalProperties" in schema and isinstance(schema["additionalProperties"], dict):
        return f"object of {_schema_type(schema['additionalProperties'])}"
    return str(t)


def _payload_section() -> list[str]:
    import contract

    out = ["## Ingest payloads by topic", "",
           "Each message of `POST /api/ingest` (and `/api/structures/{structure_id}/ingest`) carries the payload of "
           "its topic as the recording contract defines it (the same JSON schema a recording's channel carries). "
           "A payload that does not match is rejected and counted by reason, never stored.", "",
           "| topic | payload |", "| --- | --- |"]
    topics = {"shm.Imu": "`/imu/NAME` (`/imu/D` at the support)", "shm.Distance": "`/tof/NAME`, `/bearing/displacement`",
              "shm.Strain": "`/strain/NAME`", "shm.Temperature": "`/env/temperature`",
              "shm.TruthState": "`/truth/state` (simulation only)", "shm.EstimateState": "`/estimate/state` (written by the estimator)"}
    for title in contract.SCHEMAS:
        out.append(f"| {topics.get(title, '?')} | [{title}](#{title.replace('.', '').lower()}) |")
    out.append("")
    for title, schema in contract.SCHEMAS.items():
        out += [f"### {title}", "", _cell(schema.get("description", "")), "",
                "| field | type | meaning |", "| --- | --- | --- |"]
        required = set(schema.get("required", ()))
        for name, prop in schema.get("properties", {}).items():
            t = _schema_type(prop)
            if prop.get("minItems") is not None and prop.get("minItems") == prop.get("maxItems"):
                t += f" ({prop['minItems']})"
            out.append(f"| `{name}`{'' if name in required else ' (optional)'} | {t} | {_cell(prop.get('description', ''))} |")
        out.append("")
    return out


def http_page() -> str:
    from shm_service.service.http._app import create_app

    doc = create_app(object()).openapi()
    out = ["# HTTP API reference", "", GENERATED.format(what="from the service's OpenAPI document, as `/openapi.json` serves it"),
           f"{doc['info'].get('title', '')} {doc['info'].get('version', '')}. The running service also serves this "
           "document at `/openapi.json` and renders it at `/docs` and `/redoc` (offline: no CDN). On loopback the "
           "read routes are open and ingest, acknowledge and baseline need the token; on any other address every "
           "route needs it (header `Authorization: Bearer TOKEN`, or the HTTP Basic password).", "",
           "| method | path | what |", "| --- | --- | --- |"]
    ops = []
    for path, methods in doc["paths"].items():
        for method, op in methods.items():
            ops.append((path, method, op))
            anchor = f"{method}-{path}".lower().replace("/", "").replace("{", "").replace("}", "").replace("_", "")
            out.append(f"| {method.upper()} | [`{path}`](#{anchor}) | {_cell(op.get('summary', ''))} |")
    out.append("")
    out += ["## Routes", ""]
    for path, method, op in ops:
        anchor = f"{method}-{path}".lower().replace("/", "").replace("{", "").replace("}", "").replace("_", "")
        out += [f"### {method.upper()} `{path}` {{ #{anchor} }}", "", _cell(op.get("summary", "")), ""]
        if op.get("description"):
            out += [op["description"], ""]
        params = op.get("parameters", [])
        if params:
            out += ["| parameter | in | type | required | meaning |", "| --- | --- | --- | --- | --- |"]
            for p in params:
                out.append(f"| `{p['name']}` | {p['in']} | {_schema_type(p.get('schema', {}))} | "
                           f"{'yes' if p.get('required') else 'no'} | {_cell(p.get('description') or p.get('schema', {}).get('description', ''))} |")
            out.append("")
        body = op.get("requestBody", {}).get("content", {})
        for ctype, content in body.items():
            schema = content.get("schema", {})
            out += [f"Request body ({ctype}): {_schema_type(schema)}", ""]
            if path.endswith("/ingest"):
                items = schema["properties"]["messages"]["items"]
                out += ["`{\"messages\": [...]}`, each message " + _schema_type(items) + ": `topic`, `log_time_ns` "
                        "(and optionally `publish_time_ns`), and the `payload` its topic's schema types: see "
                        "[the ingest payloads](#ingest-payloads-by-topic).", ""]
            elif "properties" in schema:
                out += ["```json", json.dumps(schema, indent=1)[:4000], "```", ""]
        out += ["| status | meaning | body |", "| --- | --- | --- |"]
        for code, resp in op.get("responses", {}).items():
            schemas = [c.get("schema", {}) for c in resp.get("content", {}).values()]
            out.append(f"| {code} | {_cell(resp.get('description', ''))} | {', '.join(_schema_type(s) for s in schemas)} |")
        out.append("")
    out += _payload_section()
    out += ["## Schemas", ""]
    for name, schema in doc.get("components", {}).get("schemas", {}).items():
        out += [f"### {name}", ""]
        if schema.get("description"):
            out += [_cell(schema["description"]), ""]
        props = schema.get("properties", {})
        if props:
            required = set(schema.get("required", ()))
            out += ["| field | type | meaning |", "| --- | --- | --- |"]
            for fname, prop in props.items():
                out.append(f"| `{fname}`{'' if fname in required else ' (optional)'} | {_schema_type(prop)} | "
                           f"{_cell(prop.get('description', ''))} |")
            out.append("")
    return "\n".join(out) + "\n"


def rig_page() -> str:
    import contract

    out = ["# Recording contract and `rig.json`", "", GENERATED.format(what="from `contract.RigDescription` and `contract.SCHEMAS`"),
           "A recording is an MCAP file whose channels carry the contract's topics and JSON payloads, with the "
           "structure's description attached as `rig.json`. `shm import` writes such recordings from DAQ files, "
           "`shm inspect FILE --print-rig` prints a recording's `rig.json`, and `shm serve --source ingest --rig "
           "rig.json` takes the same payloads over HTTP. The full contract, with its signs and frames, is "
           "`recording-format.md` of the project's specifications.", ""]
    out += _model_sections(contract.RigDescription, "`rig.json` keys", 2, sections=True)
    out += ["## Extension keys", "", "Keys beyond the contract's that the project's tools write or read; any other extra key is "
            "kept and ignored.", "", "| key | meaning |", "| --- | --- |",
            *[f"| `{k}` | {_cell(v)} |" for k, v in contract.EXTENSION_KEYS.items()], ""]
    out += ["## Topics and payloads", "", "| topic | schema | payload keys |", "| --- | --- | --- |"]
    topics = {"shm.Imu": "`/imu/NAME`", "shm.Distance": "`/tof/NAME`, `/bearing/displacement`", "shm.Strain": "`/strain/NAME`",
              "shm.Temperature": "`/env/temperature`", "shm.TruthState": "`/truth/state`", "shm.EstimateState": "`/estimate/state`"}
    for title, schema in contract.SCHEMAS.items():
        keys = ", ".join(f"`{k}`" for k in schema.get("properties", {}))
        out.append(f"| {topics.get(title, '?')} | `{title}` | {keys} |")
    out += ["", "The payloads' fields, types and units are listed with the [HTTP API's ingest payloads](http-api.md#ingest-payloads-by-topic).", ""]
    return "\n".join(out) + "\n"


def _benchmarks() -> tuple[str, ...]:
    from benchmarks.__main__ import MODULES

    return MODULES


def _validation_page(name: str) -> str:
    from benchmarks._pages import RESULTS, _git

    path = RESULTS / f"{name}.md"
    head = _git("rev-parse", "--short=12", "HEAD") or "unknown"
    if not path.exists():
        return (f"# {name}\n\n!!! warning \"Not yet measured\"\n    Not yet measured by `make bench` on this commit "
                f"(`{head}`). Run `make bench` (or `python -m benchmarks --only {name}`) to write this page.\n")
    text = path.read_text()
    import re
    import subprocess

    stamped = re.search(r"^\| commit \| ([0-9a-f]{7,40})", text, re.M)
    same = False
    if stamped:  # the same code: nothing but results, documentation and other benchmarks changed since then
        changed = subprocess.run(["git", "diff", "--name-only", stamped.group(1), "HEAD", "--", ".",
                                  ":(exclude)benchmarks/results", ":(exclude)docs", ":(exclude)*.md",
                                  ":(exclude)docs_reference.py", ":(exclude)mkdocs.yml"], cwd=ROOT,
                                 capture_output=True, text=True)
        source = (ROOT / "benchmarks" / f"{name}.py").read_text()
        # this benchmark's own module and the benchmarks modules it imports measure; the others do not
        own = {f"benchmarks/{name}.py", *(f"benchmarks/{m}.py" for m in re.findall(r"benchmarks\.(\w+)", source))}
        same = changed.returncode == 0 and not [f for f in changed.stdout.split()
                                                if not f.startswith("benchmarks/") or f in own]
    if not same:
        title, _, rest = text.partition("\n")
        text = (f"{title}\n\n!!! note \"Measured on another commit\"\n    These figures were measured on the commit "
                f"stamped below, not on this one (`{head}`); `python -m benchmarks --only {name}` measures them "
                f"again.\n{rest}")
    return text


def validation_index() -> str:
    from benchmarks._pages import RESULTS

    out = ["# Validation: what was measured, when and where", "",
           "What the product's figures are, how each was measured and on what. Every page below is written by "
           "`make bench` (`python -m benchmarks`; one benchmark: `python -m benchmarks --only NAME`) into "
           "`benchmarks/results/`, stamped with the date, the commit, the machine (cores, load) and the command, "
           "and made into a page at every documentation build. A benchmark not run on a commit says so; no figure "
           "here was typed by hand. The development record in the CHANGELOG holds earlier measurements, each "
           "with its own conditions.", "",
           "| benchmark | what it measures | measured |", "| --- | --- | --- |"]
    import importlib

    for name in _benchmarks():
        try:
            doc = (importlib.import_module(f"benchmarks.{name}").__doc__ or "").strip().split("\n\n")[0]
            doc = doc.split(". ")[0].split(": ")[0].rstrip(".")  # its first clause
        except Exception as exc:  # a benchmark that cannot be imported is listed with why
            doc = f"(cannot import: {type(exc).__name__})"
        path = RESULTS / f"{name}.md"
        when = "not yet measured"
        if path.exists():
            for line in path.read_text().splitlines():
                if line.startswith("| date |"):
                    when = line.split("|")[2].strip()
                if line.startswith("| commit |"):
                    when += ", commit " + line.split("|")[2].strip()
                    break
        out.append(f"| [{name}]({name}.md) | {_cell(doc)} | {when} |")
    out += ["", "The paper's configuration study is on [its own page](study.md) (`shm study`)."]
    return "\n".join(out) + "\n"


def channel_map_page() -> str:
    from shm_service.formats.daq_import import ChannelMap, ClockMap, ColumnMap
    from shm_service.recording._plausibility import ValueLimits

    out = ["# Channel map (`shm import --map`)", "", GENERATED.format(what="from `shm_service.formats.daq_import.ChannelMap`"),
           "A channel map is a TOML file that says, for `shm import`, which column of which DAQ file fills which topic and "
           "payload field of the [recording contract](rig.md), how to scale it to SI and which clock times it. It is "
           "closed: an unknown key is an error naming it, and every topic must be a sensor of the `rig.json` given "
           "with `--rig`. Its sections:", "",
           "- `[clocks.NAME]`: one or more time bases. A clock is a time column of a file (`column`, in `unit`) or a "
           "sample rate (`rate_hz`), with the absolute time of its zero (`start` or `start_ns`). `file` names the DATA "
           "file (as given on the command line, by name or path) the clock's column is in, or whose rows it times; it "
           "may be left out when one file is imported.",
           "- `[columns.\"COLUMN\"]`: one entry per imported column, keyed by the column's name in the file (or any key, "
           "with `name` the column's name). `topic` and `field` say what it fills (`/imu/NAME` `accel` or `gyro`, "
           "`/tof/NAME` `distance`, `/strain/NAME` `strain`, `/bearing/displacement` `displacement`, "
           "`/env/temperature` `temperature`); `index` is the axis of a vector field (0 = x, 1 = y, 2 = z of the "
           "sensor frame), `SI = scale · value + offset`, and `clock` names the clock that times the column (required "
           "when the map has several; every column of a topic shares one clock). A column is read from the file of its clock.",
           "- `[limits]`: the physical limits per sensor kind in SI; a sample beyond them is rejected as implausible "
           "and counted, never written.", "",
           "An example with two loggers, each with its own file and clock:", "",
           "```toml", "[clocks.fast]", "file = \"imu.csv\"", "column = \"t\"", "unit = \"s\"",
           "start = 2026-01-01T00:00:00Z", "", "[clocks.slow]", "file = \"tof.csv\"", "rate_hz = 33.33",
           "start = 2026-01-01T00:00:00Z", "", "[columns.\"D ay\"]", "topic = \"/imu/D\"", "field = \"accel\"",
           "index = 1", "clock = \"fast\"", "", "[columns.rho1]", "topic = \"/tof/t1\"", "field = \"distance\"",
           "scale = 0.001       # mm -> m", "clock = \"slow\"", "```", "",
           "`examples/dropbear/channels.toml` is a worked map of a LabVIEW export.", ""]
    for model, title in ((ClockMap, "`[clocks.NAME]` (ClockMap)"), (ColumnMap, "`[columns.\"COLUMN\"]` (ColumnMap)"),
                         (ValueLimits, "`[limits]` (ValueLimits)")):
        rows, _ = _model_table(model)
        doc = (model.__doc__ or "").strip().split("\n\n")[0].replace("\n", " ")
        out += [f"## {title}", "", doc, "", "| key | type | default | meaning |", "| --- | --- | --- | --- |", *rows, ""]
    del ChannelMap
    return "\n".join(out) + "\n"


PAGES = {
    "reference/configuration.md": configuration_page,
    "reference/cli.md": cli_page,
    "reference/http-api.md": http_page,
    "reference/rig.md": rig_page,
    "reference/channel-map.md": channel_map_page,
}


# ---------------------------------------------------------------------------------------- the hook
def _all_pages() -> dict[str, Any]:
    pages = dict(PAGES)
    pages["validation/summary.md"] = validation_index
    for name in _benchmarks():
        pages[f"validation/{name}.md"] = (lambda n=name: _validation_page(n))
    return pages


def on_files(files: Any, config: Any) -> Any:
    from mkdocs.structure.files import File

    for uri, make in _all_pages().items():
        existing = files.get_file_from_path(uri)
        if existing is not None:
            files.remove(existing)
        files.append(File.generated(config, uri, content=make()))
    return files


def stale_reference_pages(docs: Path = ROOT / "docs") -> list[str]:
    """The reference pages (``PAGES``) whose copy under ``docs`` is missing or differs from what the
    code generates now: the checkout keeps them so that a reader finds them without a build."""
    return [uri for uri, make in PAGES.items() if not (docs / uri).exists() or (docs / uri).read_text() != make()]


if __name__ == "__main__":
    if sys.argv[1:2] == ["--reference"]:  # the checkout's copies of the reference pages: docs/reference/*.md
        for uri, make in PAGES.items():
            (ROOT / "docs" / uri).write_text(make())
            print(ROOT / "docs" / uri)
        sys.exit(0)
    target = Path(sys.argv[1] if len(sys.argv) > 1 else "site-reference")
    for uri, make in _all_pages().items():
        path = target / uri
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(make())
        print(path)
