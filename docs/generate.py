"""Write the generated reference pages: the command line from the typer app and the problem
language from the JSON Schema that bcad validates with.

    python docs/generate.py          # writes docs/reference/cli.md and docs/reference/language.md
    python docs/generate.py --check  # exit 1 if either is not what this would write

The tests run ``--check``, so the pages always describe the code they ship with.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import typer

DOCS = Path(__file__).resolve().parent
sys.path.insert(0, str(DOCS.parent))

from bcad.cli import app  # noqa: E402
from bcad.model.schema import problem_json_schema  # noqa: E402


def _cell(text: object) -> str:
    """Text fit for one cell of a Markdown table."""
    return " ".join(str(text).split()).replace("|", "\\|")


def _is_argument(parameter) -> bool:
    return parameter.param_type_name == "argument"


def _parameter_type(parameter) -> str:
    """The parameter's type in words, from its annotation (typer keeps it on the parameter)."""
    if getattr(parameter, "is_flag", False):
        return "flag"
    metavar = parameter.metavar or ""
    if metavar.startswith("[") and "|" in metavar:  # a choice: its words
        return " | ".join(f"`{choice}`" for choice in metavar.strip("[]").split("|"))
    annotation = parameter.type_descriptor.annotation
    words = {bool: "flag", int: "integer", float: "number", str: "text", Path: "path"}
    shown = f"`{metavar}`" if metavar.strip() else ""  # a value's form (NAME=VALUE), as --help shows it
    if getattr(annotation, "__origin__", None) is list:
        (item,) = annotation.__args__
        return f"{shown or words.get(item, item.__name__)}, repeatable"
    return shown or words.get(annotation, getattr(annotation, "__name__", str(annotation)))


def _default(parameter) -> str:
    if parameter.required and not _is_argument(parameter):
        return "required"
    default = parameter.default
    if (
        default is None
        or default in ((), [])
        or callable(default)
        or (getattr(parameter, "is_flag", False) and not default)
    ):
        return ""
    return f"`{default}`"


#: what a reference page says of the papers' numbers it cites
CITATIONS = (
    "Numbers such as Eq. 2, Sect. 4.2.1 or Table 2 refer to the papers bcad implements; "
    "[the theory](../theory.md) writes their equations out and names the papers."
)


def cli_page() -> str:
    root = typer.main.get_command(app)
    lines = [
        "# Command line reference",
        "",
        "Generated from the command's own definitions (`python docs/generate.py`); "
        "`bcad COMMAND --help` prints the same. " + CITATIONS,
        "",
    ]
    lines += ["## bcad", "", _cell(root.help or ""), "", "| option | type | default | meaning |", "|---|---|---|---|"]
    lines += _options(root)
    for name, command in sorted(root.commands.items()):
        arguments = " ".join(
            parameter.name.upper() + ("..." if parameter.nargs == -1 else "")
            for parameter in command.params
            if _is_argument(parameter)
        )
        lines += ["", f"## bcad {name}", "", f"`bcad {name} {arguments} [OPTIONS]`".replace("  ", " "), ""]
        lines += [(command.help or "").strip(), ""]
        lines += ["| argument or option | type | default | meaning |", "|---|---|---|---|"]
        lines += _options(command)
    return "\n".join(lines).rstrip() + "\n"


def _options(command) -> list[str]:
    rows = []
    for parameter in command.params:
        if parameter.name == "help" or getattr(parameter, "hidden", False):
            continue
        if _is_argument(parameter):
            label = f"`{parameter.name.upper()}`"
            meaning = getattr(parameter, "help", "") or ""
        else:
            label = ", ".join(f"`{option}`" for option in [*parameter.opts, *parameter.secondary_opts])
            meaning = parameter.help or ""
        rows.append(f"| {label} | {_cell(_parameter_type(parameter))} | {_default(parameter)} | {_cell(meaning)} |")
    return rows


def _type_of(schema: dict) -> str:
    if "$ref" in schema:
        name = schema["$ref"].rsplit("/", 1)[-1]
        return f"[{name}](#{name.lower()})"
    for key in ("anyOf", "oneOf"):
        if key in schema:
            kinds = [_type_of(member) for member in schema[key]]
            return " or ".join(dict.fromkeys(kinds))
    if "const" in schema:
        return f"`{schema['const']!r}`".replace("'", '"')
    if "enum" in schema:
        return " | ".join(f"`{value}`" for value in schema["enum"])
    kind = schema.get("type", "any")
    if kind == "array":
        if "prefixItems" in schema:
            return "[" + ", ".join(_type_of(item) for item in schema["prefixItems"]) + "]"
        return f"list of {_type_of(schema.get('items', {}))}"
    if kind == "object" and "additionalProperties" in schema and isinstance(schema["additionalProperties"], dict):
        return f"mapping to {_type_of(schema['additionalProperties'])}"
    return str(kind) if not isinstance(kind, list) else " or ".join(kind)


def _bounds(schema: dict) -> str:
    found = []
    for member in [schema, *schema.get("anyOf", []), *schema.get("oneOf", [])]:
        for key, word in (
            ("minimum", "≥"),
            ("exclusiveMinimum", ">"),
            ("maximum", "≤"),
            ("exclusiveMaximum", "<"),
            ("minLength", "length ≥"),
            ("maxLength", "length ≤"),
            ("minItems", "items ≥"),
            ("maxItems", "items ≤"),
            ("pattern", "matches"),
        ):
            if key in member:
                value = member[key]
                found.append(
                    f"{word} `{value}`"
                    if key == "pattern"
                    else f"{word} {value:g}"
                    if isinstance(value, (int, float))
                    else f"{word} {value}"
                )
    return ", ".join(dict.fromkeys(found))


def _schema_tables(schema: dict, first: list[str]) -> list[str]:
    """One table per definition of a JSON Schema: each key's type, whether required, default,
    bounds and meaning."""
    definitions = schema["$defs"]
    lines: list[str] = []
    for name in [*first, *sorted(set(definitions) - set(first))]:
        definition = definitions[name]
        lines += [f"## {name}", ""]
        if definition.get("description"):
            lines += [" ".join(definition["description"].split()), ""]
        properties = definition.get("properties")
        if not properties:
            lines += [f"Type: {_type_of(definition)}", ""]
            continue
        required = set(definition.get("required", []))
        lines += ["| key | type | required | default | bounds | meaning |", "|---|---|---|---|---|---|"]
        for key, prop in properties.items():
            default = f"`{json.dumps(prop['default'])}`" if "default" in prop else ""
            lines.append(
                f"| `{key}` | {_cell(_type_of(prop))} | {'yes' if key in required else ''} | "
                f"{_cell(default)} | {_cell(_bounds(prop))} | {_cell(prop.get('description', ''))} |"
            )
        lines.append("")
    return lines


def language_page() -> str:
    lines = [
        "# Problem language reference",
        "",
        "Every key of a problem file, generated from the schemas bcad validates with "
        "(`python docs/generate.py`; `bcad schema` prints the same as JSON Schema). "
        "A problem file is a [Problem](#problem) (a kinematic graph) or a "
        "[ChainProblem](#chainproblem) (a clearance chain for `bcad maxerror`). "
        "The [user guide](../guide/language.md) explains what the keys mean together. " + CITATIONS,
        "",
    ]
    lines += _schema_tables(problem_json_schema(), ["Problem", "ChainProblem"])
    return "\n".join(lines).rstrip() + "\n"


def results_page() -> str:
    from bcad.model.results import SCHEMA_VERSION
    from bcad.result import results_json_schema

    lines = [
        "# Result documents reference",
        "",
        f"Every key of the JSON documents bcad writes (schema_version {SCHEMA_VERSION}), generated from the "
        "models each family checks its result with (`python docs/generate.py`; `bcad schema --results` prints "
        "the same as JSON Schema, `schema/results.schema.json` is its copy). A document's `kind` names the "
        "command that wrote it: [DesignResult](#designresult) for `solve` and `posterior`, "
        "[MaxErrorResult](#maxerrorresult) for `maxerror`, [CalibrationResult](#calibrationresult) for "
        "`calibrate`. Keys not listed here may appear (diagnostics, and keys later versions add): readers "
        "ignore what they do not know. In Python, `result.typed` is the document as its model, and its "
        "fields are the result's own (`bcad.maxerror(...).rotation.upper_bound`).",
        "",
    ]
    lines += _schema_tables(results_json_schema(), ["DesignResult", "MaxErrorResult", "CalibrationResult"])
    return "\n".join(lines).rstrip() + "\n"


PAGES = {"reference/cli.md": cli_page, "reference/language.md": language_page, "reference/results.md": results_page}


def main() -> int:
    check = "--check" in sys.argv[1:]
    stale = []
    for relative, make in PAGES.items():
        path = DOCS / relative
        text = make()
        if check:
            if not path.exists() or path.read_text(encoding="utf-8") != text:
                stale.append(relative)
        else:
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(text, encoding="utf-8")
    if stale:
        print("out of date (run python docs/generate.py): " + ", ".join(stale), file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
