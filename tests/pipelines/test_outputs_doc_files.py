"""docs/outputs.md's tables of the files the zoo and the data commands keep, against files they write: every
key of each object is a row of its table, every row a key some file has, and each value of the row's type
(the `type` column: `string`, `integer`, `number`, `boolean`, `object`, `null`, `list of Xs`, joined by
`or`). The other tests of the doc ask that a name appear somewhere in it; these, that it be in its table."""

from __future__ import annotations

import re
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from pipelines.cli import main
from tests.pipelines.test_outputs_doc import DOC, _strict
from tests.predictors.samples import write_crowds

REPO = Path(__file__).resolve().parents[2]
SCALARS: dict[str, tuple[type, ...]] = {
    "string": (str,),
    "number": (int, float),
    "integer": (int,),
    "boolean": (bool,),
    "object": (dict,),
    "null": (type(None),),
}


def doc_table(heading: str, index: int = 0) -> dict[str, dict[str, str]]:
    """The ``index``-th table of outputs.md's section ``heading`` (its ``## `` line, without the marks):
    each name its first column gives (`a`, `b`: two names) -> the row's cells by column name."""
    text = DOC.read_text(encoding="utf-8")
    start = text.index(f"\n## {heading}\n")
    section = text[start + 1 :].split("\n## ", 1)[0]
    tables = re.findall(r"(?:^\|.*\n)+", section, re.M)
    header, _, *rows = tables[index].splitlines()
    columns = [cell.strip() for cell in header.strip("|").split("|")]
    table: dict[str, dict[str, str]] = {}
    for row in rows:
        cells = [cell.strip() for cell in re.split(r"(?<!\\)\|", row.strip().strip("|"))]
        for name in re.findall(r"`([^`]+)`", cells[0]):
            table[name] = dict(zip(columns, cells, strict=True))
    return table


def of_type(value: Any, spec: str) -> bool:
    """Whether ``value`` is of the doc's type ``spec`` ("string or null", "list of lists of numbers")."""
    for kind in spec.split(" or "):
        if kind.startswith("list of "):
            plural, _, rest = kind.removeprefix("list of ").partition(" ")
            item = " ".join(filter(None, (plural.removesuffix("s"), rest)))
            if isinstance(value, list) and all(of_type(v, item) for v in value):
                return True
        elif isinstance(value, SCALARS[kind]) and (
            kind in ("boolean", "object") or not isinstance(value, bool)
        ):
            return True
    return False


def check_documented(table: Mapping[str, Mapping[str, str]], objects: Iterable[Mapping[str, Any]]) -> None:
    """Each key of ``objects`` a row of ``table``, each value of its row's type, and each row a key of one
    of them."""
    seen: set[str] = set()
    wrong = []
    for obj in objects:
        for key, value in obj.items():
            seen.add(key)
            if key not in table:
                wrong.append(f"{key}: not in the table")
            elif not of_type(value, table[key]["type"]):
                wrong.append(f"{key}: {value!r:.60} is not {table[key]['type']}")
    wrong += [f"{key}: in the table, in no file" for key in table if key not in seen]
    assert sorted(set(wrong)) == []


def test_the_type_names_read_as_the_doc_means_them():
    assert of_type(3, "integer") and of_type(3, "number") and not of_type(3.0, "integer")
    assert not of_type(True, "integer") and of_type(None, "string or null") and not of_type(None, "string")
    assert of_type([[1, 2.5]], "list of lists of numbers") and not of_type(
        [[1, "a"]], "list of lists of numbers"
    )
    assert of_type([], "list of objects") and not of_type({}, "list of objects")


def test_the_zoo_manifest_is_as_documented(tmp_path, monkeypatch):
    """manifest.json, the list of a zoo's models, had no reference: its entries' fields were named nowhere."""
    data = str(write_crowds(tmp_path / "crowds.ndjson"))
    argv = ["train", "--model", "vanilla_lstm", "--train", data, "--val", data, "--epochs", "1"]
    assert main([*argv, "--batch-size", "2", "--no-progress", "--out", str(tmp_path / "run")]) == 0
    monkeypatch.setenv("CROWDMPC_ZOO", str(tmp_path / "zoo"))
    assert main(["zoo", "add", str(tmp_path / "run" / "vanilla_lstm_custom.pt")]) == 0
    heading = "The zoo's `manifest.json` (`crowdmpc zoo add`)"
    manifests = [
        _strict((zoo / "manifest.json").read_text()) for zoo in (tmp_path / "zoo", REPO / "checkpoints")
    ]
    check_documented(doc_table(heading, 0), manifests)
    check_documented(doc_table(heading, 1), [entry for m in manifests for entry in m["models"]])


def test_calibrations_json_is_as_documented(tmp_path):
    """calibrations.json's layout around its blocks was named nowhere, and its blocks' table gave no types."""
    argv = ["calibrate", "--predictor", "constant_velocity", "--source", "closed-loop", "--episodes", "2"]
    assert main([*argv, "--humans", "5", "--alpha", "0.5", "--no-progress"]) == 0  # stored: margins per class
    from predictors.zoo import user_zoo_dir

    heading = "`crowdmpc calibrate --json FILE`"
    files = [
        _strict((zoo / "calibrations.json").read_text()) for zoo in (user_zoo_dir(), REPO / "checkpoints")
    ]
    check_documented(doc_table(heading, 0), files)
    blocks = [block for file in files for block in file["calibrations"]]
    assert {block["source"] for block in blocks} == {"real", "closed-loop"}
    check_documented(doc_table(heading, 2), blocks)
