"""Errors a user can cause through predictors and data. The CLI prints these without a traceback."""

from __future__ import annotations

from pathlib import Path


def short_repr(value: object, limit: int = 60) -> str:
    """``repr(value)`` cut to ``limit`` characters: a hostile file's value must not flood a one-line error."""
    text = repr(value)
    return text if len(text) <= limit else f"{text[: limit - 3]}..."


def short_key(key: str, limit: int = 60) -> str:
    """A JSON key of a user's file as a one-line error names it: cut as ``short_repr`` cuts, and written with
    ASCII escapes, so that a key spelt with a look-alike letter (a Cyrillic 'е' in 'seed') or a combining
    mark does not read as the key the same line lists as allowed."""
    text = ascii(key)
    return text if len(text) <= limit else f"{text[: limit - 3]}..."


class PredictorError(ValueError):
    """Base class of the user-facing errors raised by `predictors`."""


class DuplicateKey(PredictorError):
    """A JSON object that names a key twice (``unique_keys``). Its message carries the advice, so that every
    file read with ``unique_keys`` says the same (the readers prefix the file's path or option)."""

    def __init__(self, key: str):
        super().__init__(
            f"the key {short_key(key)} appears twice in one object; "
            "give each key once (json would keep the last)"
        )
        self.key = key


def unique_keys(pairs: list[tuple[str, object]]) -> dict[str, object]:
    """json's ``object_pairs_hook`` for the files a user may edit by hand (zoo manifests, predictor configs,
    calibration files, train_settings.json): json keeps the last of a key given twice without a word, so a
    value typed above the one already there did nothing. The object, or DuplicateKey naming the key."""
    document = dict(pairs)
    if len(document) < len(pairs):
        seen: set[str] = set()
        for key, _ in pairs:
            if key in seen:
                raise DuplicateKey(key)
            seen.add(key)
    return document


class NoCasadiTwin(PredictorError):
    """A predictor that has no CasADi function at all (the ORCA oracle): the iterative best response then
    predicts with it numerically, and the coupled NLP cannot use it. A twin that exists but fails its
    export or its check against torch is another error (``predictors.export.ExportError``)."""


class DatasetFormatError(PredictorError):
    """A dataset file that does not follow the TrajNet++ ndjson format (or raw obsmat.txt)."""

    def __init__(self, path: str | Path, line: int | None, reason: str):
        self.path = str(path)
        self.line = line
        self.reason = reason
        where = f"{self.path}:{line}" if line is not None else self.path
        super().__init__(f"{where}: {reason}")

    def __reduce__(self) -> tuple[type, tuple[object, ...]]:
        # Built from its facts, not its message: a process pool sends a job's exception back pickled, and
        # BaseException's pickle calls the class with the message alone (a TypeError, the pool broken).
        return type(self), (self.path, self.line, self.reason)


class UnknownPredictor(PredictorError):
    def __init__(self, name: str, choices: list[str]):
        self.name = name
        self.choices = choices
        super().__init__(f"unknown predictor {short_repr(name)}; choose from {choices}{_unknown_hint(name)}")

    def __reduce__(self) -> tuple[type, tuple[object, ...]]:
        return type(self), (self.name, self.choices)  # see DatasetFormatError.__reduce__


def _unknown_hint(name: object) -> str:
    """What a name of the wrong kind needs: a weights file, or a net class, is no predictor's name yet."""
    if not isinstance(name, str):
        return ""
    if name.endswith(".pt") or "/" in name:
        return " (a weights file joins the zoo first: `crowdmpc zoo add FILE.pt`, then its name)"
    if ":" in name:
        return " (module:Class names a net to train, not a trained model: train it, zoo add it, use its name)"
    return ""


class CheckpointMismatch(PredictorError):
    """A checkpoint file whose sha256 differs from the one the zoo manifest records."""

    def __init__(self, path: str | Path, expected: str, found: str):
        self.path = str(path)
        self.expected = expected
        self.found = found
        super().__init__(
            f"{self.fault}: restore it, or add the model again (`crowdmpc zoo add ... --replace`); "
            "`crowdmpc zoo verify` lists every entry whose files differ"
        )

    @property
    def fault(self) -> str:
        """What is wrong, without what to do: ``zoo verify`` says that in its own words."""
        return (
            f"checkpoint {self.path} has sha256 {self.found}, but the manifest expects {self.expected}; "
            "the file is corrupt or was replaced"
        )

    def __reduce__(self) -> tuple[type, tuple[object, ...]]:
        return type(self), (self.path, self.expected, self.found)  # see DatasetFormatError.__reduce__
