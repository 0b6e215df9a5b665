"""The commonroad-reactive-planner baseline (mpcdrive.bench.reactive) is optional: without the
planner it says how to get it and nothing else in mpcdrive needs it. These tests hide the
planner, so they run the same whether it is installed or not."""

import gzip
import re
import subprocess
import sys
from pathlib import Path

import pytest

from mpcdrive.bench import reactive

SRC = Path(reactive.__file__).resolve().parents[1]


@pytest.fixture
def no_planner(monkeypatch):
    monkeypatch.setitem(sys.modules, "commonroad_rp", None)  # any import of it raises ImportError


def test_missing_planner_raises_a_clear_error(no_planner):
    with pytest.raises(reactive.ReactivePlannerMissing, match="pip install commonroad-reactive-planner"):
        reactive.load_planner()
    with pytest.raises(ImportError, match="not installed"):  # not swallowed into a file's result
        reactive.bench_file("any.xml")


def test_cli_without_planner_exits_2_with_the_hint(no_planner, capsys, tmp_path):
    out = tmp_path / "out.json"
    assert reactive.main(["x.xml", "--repeat", "1", "--json", str(out)]) == 2
    assert "commonroad-reactive-planner is not installed" in capsys.readouterr().err
    assert not out.exists()


def test_call_times_in_milliseconds():
    t = reactive.CallTimes.of([0.010, 0.020, 0.030])
    assert (t.calls, t.median_ms, t.mean_ms, t.max_ms) == (3, 20.0, 20.0, 30.0)
    assert 29.0 < t.p99_ms <= 30.0
    assert reactive.CallTimes.of([]) == reactive.CallTimes()


def test_reads_gzip_compressed_files(tmp_path):
    class Reader:
        def __init__(self, path):
            self.path = Path(path)

        def open(self):
            return self.path.name, self.path.read_text()

    (tmp_path / "a.xml").write_text("<plain/>")
    (tmp_path / "b.xml.gz").write_bytes(gzip.compress(b"<packed/>"))
    assert reactive.read_file(Reader, tmp_path / "a.xml") == ("a.xml", "<plain/>")
    assert reactive.read_file(Reader, tmp_path / "b.xml.gz") == ("b.xml", "<packed/>")


def test_nothing_in_mpcdrive_imports_the_baseline():
    imports_it = re.compile(
        r"^\s*(from\s+\S*reactive\s+import|import\s+\S*bench\.reactive|from\s+\S*\s+import\s.*\breactive\b)", re.M
    )
    users = [str(p.relative_to(SRC)) for p in SRC.rglob("*.py") if imports_it.search(p.read_text(encoding="utf-8"))]
    assert not users, users
    code = "import sys, mpcdrive.bench, mpcdrive.bench.reactive; print(sorted(m for m in sys.modules if m.startswith('mpcdrive.control')))"
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert done.stdout.strip() == "[]", "importing the helper pulls in the controller"
