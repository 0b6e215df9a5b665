"""Opening a CommonRoad scenario file, plain or gzip-compressed (standard library only, so that
helpers run outside mpcdrive's own environment, such as ``mpcdrive.bench.reactive``, can use it)."""

from __future__ import annotations

import gzip
import tempfile
from pathlib import Path
from typing import Any

__all__ = ["read_file"]


def read_file(reader: Any, file: Path) -> tuple[Any, Any]:
    """(scenario, planning problem set) that ``reader`` (commonroad-io's ``CommonRoadFileReader``)
    opens from a ``.xml`` file or a gzip-compressed ``.xml.gz`` (unpacked to a temporary file)."""
    file = Path(file)
    if not file.name.endswith(".gz"):
        return reader(str(file)).open()
    with tempfile.TemporaryDirectory() as tmp:
        plain = Path(tmp) / file.name.removesuffix(".gz")
        plain.write_bytes(gzip.decompress(file.read_bytes()))
        return reader(str(plain)).open()
