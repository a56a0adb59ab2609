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


#: Packages beside the core whose code shapes what a stage writes (the adapters that write each
#: stage's Parquet and its metadata, the schemas that validate it): in the code version, so a
#: change there is not served a cached output either.  The flows (the order of stages) are not.
STAGE_PACKAGES = ("tasks", "schemas")


def hashed_source_files() -> list[Path]:
    """The files code_version hashes: the core's sources and built-in data (``*.py``, ``*.toml``,
    ``*.csv`` under aerosid/) and the sources of STAGE_PACKAGES where they sit beside it."""
    root = Path(__file__).parent
    files = [p for pattern in ("*.py", "*.toml", "*.csv") for p in root.rglob(pattern)]
    for name in STAGE_PACKAGES:
        pkg = root.parent / name
        if (pkg / "__init__.py").is_file():
            files += list(pkg.rglob("*.py"))
    return sorted(p for p in files if "__pycache__" not in p.parts)


@functools.lru_cache(maxsize=1)
def code_version() -> str:
    """``<package version>+<12 hex of the SHA-256 of hashed_source_files()>``: changes whenever
    any numerical code, built-in data, stage adapter or schema changes (a stage's cache key holds
    it, so no output written by other code is reused)."""
    base = Path(__file__).parent.parent
    h = hashlib.sha256()
    for path in hashed_source_files():
        h.update(str(path.relative_to(base)).encode())
        h.update(path.read_bytes())
    try:
        version = metadata.version("aerosid")
    except metadata.PackageNotFoundError:  # pragma: no cover - running from a source tree
        version = "0+unknown"
    return f"{version}+{h.hexdigest()[:12]}"
