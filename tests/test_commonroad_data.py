"""The CommonRoad test files are the published files, byte for byte (checksums in their README)."""

import gzip
import hashlib
import re
from pathlib import Path

import pytest

DIR = Path(__file__).resolve().parent / "data" / "commonroad"


def _published_checksums() -> dict[str, str]:
    text = (DIR / "README.md").read_text()
    return dict((name, sha) for sha, name in re.findall(r"^([0-9a-f]{64})  (\S+\.xml)$", text, re.M))


def test_every_listed_file_is_present_and_listed_files_only():
    listed = _published_checksums()
    assert len(listed) == 32
    stored = {p.name.removesuffix(".gz") for p in DIR.iterdir() if p.name.endswith((".xml", ".xml.gz"))}
    assert stored == set(listed)


@pytest.mark.parametrize("name", sorted(_published_checksums()))
def test_file_bytes_match_the_published_checksum(name):
    plain = DIR / name
    data = plain.read_bytes() if plain.exists() else gzip.decompress((DIR / f"{name}.gz").read_bytes())
    assert hashlib.sha256(data).hexdigest() == _published_checksums()[name]
