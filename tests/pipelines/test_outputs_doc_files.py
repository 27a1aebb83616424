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
from tests.predictors.samples import write_crowds, write_tiny_ewap

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
    """The ``index``-th table of outputs.md's section ``heading`` (its ``## `` or ``### `` line, without the
    marks; up to the next heading of its level or above): each name its first column gives (`a`, `b`: two
    names) -> the row's cells by column name, a type column of as many types as names ("integer, string")
    giving each name its own."""
    text = DOC.read_text(encoding="utf-8")
    found = re.search(rf"^(##+) {re.escape(heading)}\n", text, re.M)
    assert found is not None, f"no section {heading!r} in {DOC.name}"
    section = re.split(rf"^#{{2,{len(found[1])}}} ", text[found.end() :], maxsplit=1, flags=re.M)[0]
    tables = re.findall(r"(?:^\|.*\n)+", section, re.M)
    header, _, *rows = tables[index].splitlines()
    columns = [cell.strip() for cell in header.strip("|").split("|")]
    table: dict[str, dict[str, str]] = {}
    for row in rows:
        cells = [cell.strip() for cell in re.split(r"(?<!\\)\|", row.strip().strip("|"))]
        names = re.findall(r"`([^`]+)`", cells[0])
        row = dict(zip(columns, cells, strict=True))
        types = row.get("type", "").split(", ")
        for i, name in enumerate(names):  # `a`, `b` | integer, string: a's type, then b's
            table[name] = row | ({"type": types[i]} if len(types) == len(names) else {})
    return table


def of_type(value: Any, spec: str) -> bool:
    """Whether ``value`` is of the doc's type ``spec`` ("string or null", "null or list of numbers"); a list's
    item types run to the end ("list of integers or nulls": each item an integer or null)."""
    scalars, _, items = spec.partition("list of ")
    for kind in filter(None, scalars.split(" or ")):
        if isinstance(value, SCALARS[kind]) and (
            kind in ("boolean", "object") or not isinstance(value, bool)
        ):
            return True
    if not items or not isinstance(value, list):
        return False
    item = " or ".join(_singular(kind) for kind in items.split(" or "))
    return all(of_type(v, item) for v in value)


def _singular(kind: str) -> str:
    """ "integers" -> "integer", "lists of numbers" -> "list of numbers"."""
    first, _, rest = kind.partition(" ")
    return " ".join(filter(None, (first.removesuffix("s"), rest)))


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
    assert of_type([1, None], "list of integers or nulls") and not of_type(None, "list of integers or nulls")
    assert of_type(None, "null or list of numbers") and of_type([0.1], "null or list of numbers")


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


def test_prepared_datas_manifest_is_as_documented(tmp_path):
    """data prepare's manifest.json, which every reader of the prepared data checks, was named as "sources
    (sha256), parameters, per-file scene counts and sha256, self-check results" and no further."""
    raw = write_tiny_ewap(tmp_path / "data")
    argv = ["data", "prepare", "--raw", str(raw)]
    assert main([*argv, "--out", str(tmp_path / "first"), "--no-tags"]) == 0
    reference = tmp_path / "data" / "trajnetpp_vita" / "train" / "real_data" / "biwi_hotel.ndjson"
    reference.parent.mkdir(parents=True)
    reference.write_bytes((tmp_path / "first" / "train" / "biwi_hotel.ndjson").read_bytes())
    assert main([*argv, "--out", str(tmp_path / "checked")]) == 0  # tagged, and checked against the reference
    manifests = [_strict((tmp_path / out / "manifest.json").read_text()) for out in ("first", "checked")]
    heading = "`crowdmpc data prepare --out DIR`"
    check_documented(doc_table(heading, 0), manifests)
    check_documented(doc_table(heading, 1), [m["parameters"] for m in manifests])
    check_documented(doc_table(heading, 2), [s for m in manifests for s in m["sources"].values()])
    check_documented(doc_table(heading, 3), [f for m in manifests for f in m["files"].values()])
    checks = [c for m in manifests for c in m["self_check"].values()]
    assert len(checks) == 1
    check_documented(doc_table(heading, 4), checks)


def test_a_synthetic_files_provenance_is_as_documented(tmp_path):
    """NAME.synth.json, from which a synthetic set is made again, was named as "options, sha256, code"."""
    argv = ["data", "synth", "--episodes", "1", "--humans", "3", "--seed", "0", "--no-progress"]
    assert main([*argv, "--out", str(tmp_path / "a.ndjson")]) == 0
    assert main([*argv, "--out", str(tmp_path / "b.ndjson"), "--with-robots", "--profile", "v1"]) == 0
    documents = [_strict((tmp_path / f"{name}.synth.json").read_text()) for name in "ab"]
    heading = "`crowdmpc data synth --out FILE`"
    check_documented(doc_table(heading, 0), documents)
    check_documented(doc_table(heading, 1), [d["options"] for d in documents])
    check_documented(doc_table(heading, 2), [d["summary"] for d in documents])
    assert documents[1]["options"]["profile"] == "v1" and "profile" not in documents[0]["options"]
