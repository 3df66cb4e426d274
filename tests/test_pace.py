"""The machine's pace (the bundled arm's engine loop, one thread's dense arithmetic) and its processor."""

from __future__ import annotations

from pathlib import Path

import pytest

from armreach_core.diagnostics.machine import cpu_count, cpu_name, machine
from armreach_core.diagnostics.pace import dense_pace, measure_pace
from tests.conftest import BACKENDS

pytest.importorskip("torch")


@pytest.mark.skipif("pybullet" not in BACKENDS, reason="times the PyBullet engine loop")
def test_the_pace_times_the_engine_loop_and_one_thread_of_dense_arithmetic() -> None:
    import torch

    before = torch.get_num_threads()
    torch.set_num_threads(2)
    try:
        pace = measure_pace(["pybullet"], steps=200, repeats=1)
        assert torch.get_num_threads() == 2  # the probe's one thread is given back
    finally:
        torch.set_num_threads(before)
    (rate,) = pace.engine.values()
    # a bare loop of the bundled arm runs thousands of steps/s here; a dense product of the
    # paper's size tens of GFLOP/s: anything far outside is a broken probe, not a slow hour
    assert 200 < rate < 200_000 and 1.0 < pace.dense < 2_000
    assert 1.0 < dense_pace(products=20, repeats=1) < 2_000
    assert pace.cpu == cpu_name() != ""


def test_the_pace_names_the_first_processor_with_its_family_and_model(tmp_path: Path) -> None:
    block = "processor\t: {0}\nvendor_id\t: AuthenticAMD\ncpu family\t: 25\nmodel\t\t: 17\nmodel name\t: AMD EPYC\n"
    cpuinfo = tmp_path / "cpuinfo"
    cpuinfo.write_text(block.format(0) + "\n" + block.format(1).replace("EPYC", "EPYC 7B13").replace(": 17", ": 1"))
    assert cpu_name(cpuinfo) == "AMD EPYC, family 25, model 17"
    # a system without cpuinfo (or one that names no model) still gets a name
    assert cpu_name(tmp_path / "none") != ""


def test_the_machine_line_names_the_processor_and_the_cores_this_process_may_use() -> None:
    line = machine()
    assert f"({cpu_name()}), {cpu_count()} CPU cores, Python " in line and cpu_count() >= 1
