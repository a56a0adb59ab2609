"""Content hashes and code version for lineage and cache keys (no paths involved)."""
from __future__ import annotations

import functools
import hashlib
import json
from importlib import metadata
from pathlib import Path

_CHUNK = 1 << 20


def sha256_file(path: str | Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(_CHUNK), b""):
            h.update(block)
    return h.hexdigest()


def params_hash(params) -> str:
    """SHA-256 of a JSON-able parameter mapping (keys sorted, floats by repr)."""
    text = json.dumps(params, sort_keys=True, default=repr, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


@functools.lru_cache(maxsize=1)
def code_version() -> str:
    """``<package version>+<12 hex of the SHA-256 of the core's source files and data>``:
    changes whenever any numerical code or built-in data changes."""
    root = Path(__file__).parent
    h = hashlib.sha256()
    for path in sorted(list(root.rglob("*.py")) + list(root.rglob("*.toml")) + list(root.rglob("*.csv"))):
        if "__pycache__" in path.parts:
            continue
        h.update(str(path.relative_to(root)).encode())
        h.update(path.read_bytes())
    try:
        version = metadata.version("aerosid")
    except metadata.PackageNotFoundError:  # pragma: no cover - running from a source tree
        version = "0+unknown"
    return f"{version}+{h.hexdigest()[:12]}"
