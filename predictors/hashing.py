"""Content hashes of files: what the zoo manifest, the prepared-data manifest and the scene cache key on."""

from __future__ import annotations

import hashlib
import re
from pathlib import Path
from typing import Final, TypeGuard

# A sha256 as crowdmpc records one (zoo manifests and configs, calibration blocks): 64 lowercase hex digits,
# what ``hexdigest`` writes.
SHA256_PATTERN: Final[re.Pattern[str]] = re.compile(r"[0-9a-f]{64}")


def is_sha256(value: object) -> TypeGuard[str]:
    """Whether ``value`` is a sha256 as recorded (``SHA256_PATTERN``)."""
    return isinstance(value, str) and SHA256_PATTERN.fullmatch(value) is not None


def sha256_file(path: str | Path) -> str:
    """Hex sha256 of a file's bytes, read in 1 MiB blocks so large datasets need no memory."""
    digest = hashlib.sha256()
    with Path(path).open("rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()
