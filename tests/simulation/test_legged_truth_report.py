"""benchmarks/legged_truth.py's report header: one entry per section run, replaced on rerun."""

from __future__ import annotations

import argparse
import sys

import pytest

pytest.importorskip("mujoco")

from tests.io.test_real_data import bench_module


def args(*sections: str, **more: object) -> argparse.Namespace:
    bench = bench_module("legged_truth")
    base = {
        "sections": list(sections),
        "motions": list(bench.LEGGED_MOTIONS),
        "long": 60.0,
        "humanoid_motions": list(bench.HUMANOID_MOTIONS),
    }
    return argparse.Namespace(**{**base, **more})


def test_a_rerun_replaces_its_sections_entry_and_keeps_the_others(monkeypatch) -> None:
    bench = bench_module("legged_truth")
    report: dict = {}
    monkeypatch.setattr(sys, "argv", ["legged_truth.py", "--sections", "real", "slip"])
    bench.record_run(report, args("real", "slip"), 100.0, "1.0 → 1.5")
    assert list(report["runs"]) == ["real", "slip"]
    assert report["runs"]["real"]["seconds"] == 100.0
    assert report["runs"]["real"]["command"].endswith("--sections real slip")
    monkeypatch.setattr(sys, "argv", ["legged_truth.py", "--sections", "real", "--merge"])
    bench.record_run(report, args("real"), 50.0, "2.0 → 2.0")
    assert (
        report["runs"]["real"]["seconds"] == 50.0 and report["runs"]["real"]["load"] == "2.0 → 2.0"
    )
    assert report["runs"]["slip"]["seconds"] == 100.0  # kept
    assert list(report["runs"]) == ["slip", "real"]


def test_a_partial_rerun_replaces_only_its_rows_and_a_whole_one_replaces_them_all() -> None:
    bench = bench_module("legged_truth")
    report: dict = {}
    bench.record_run(report, args("humanoid", humanoid_motions=["step"]), 1.0, "")
    bench.record_run(report, args("rolling", motions=["trot"], long=0.0), 2.0, "")
    assert set(report["runs"]) == {"humanoid step", "rolling trot"}
    bench.record_run(report, args("rolling", motions=["stand"], long=0.0), 3.0, "")
    assert set(report["runs"]) == {"humanoid step", "rolling trot", "rolling stand"}
    bench.record_run(report, args("rolling"), 4.0, "")
    bench.record_run(report, args("humanoid"), 5.0, "")
    assert report["runs"] == {
        "rolling": report["runs"]["rolling"],
        "humanoid": report["runs"]["humanoid"],
    }
    assert report["runs"]["rolling"]["seconds"] == 4.0


def test_the_header_is_short_and_lists_each_section_with_its_note() -> None:
    bench = bench_module("legged_truth")
    report = {key: {} for key in bench.SECTIONS}
    report["machine"] = {"python": "3.11", "mujoco": "4.0.1"}
    bench.record_run(report, args("density"), 13.0, "1.0 → 1.0")
    md = bench.format_report(report)
    first, rest = md.split("\n\n", 1)
    assert len(first) < 600 and "MuJoCo 4.0.1" in first
    line = next(x for x in rest.splitlines() if x.startswith("* `density`"))
    assert "13 s" in line and bench.NOTES["density"][:20] in line
