"""The hostile probe (``tools/hostile_probe.py``, a test tool) stays runnable and its
fourth wave's quick surface stays clean: pick's targets and hands (each case a forked
``handle-drake pick`` that must exit 2 with one line naming the field, nothing written,
before any work)."""

import importlib.util
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _probe():
    spec = importlib.util.spec_from_file_location("hostile_probe",
                                                  ROOT / "tools" / "hostile_probe.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_probe_is_a_test_tool_not_a_benchmark():
    assert not (ROOT / "benchmarks" / "hostile_probe.py").exists()
    assert "tools/hostile_probe.py" in (ROOT / "docs" / "results" / "hostile_probe.md") \
        .read_text()


def test_the_fourth_wave_pick_targets_are_refused_cleanly(tmp_path, monkeypatch):
    probe = _probe()
    monkeypatch.chdir(tmp_path)
    probe.probe_fourth_wave(tmp_path, only="pick targets")
    result = probe.RESULTS["pick targets"]
    assert result["tried"] == 3 and result["clean"] == 3, result["failures"]
