"""``adaptive``'s fused update (:mod:`pinobs.observers.adaptive_fused`, issue 39): a plain
update with a sample in one Python call around compiled ones gives what the base's path gives,
bit for bit, learning included (synchronous, and in the background given the time to finish),
on varied inputs; and it is the path a plain sample takes."""

from __future__ import annotations

import math

import numpy as np
import pytest

import pinobs
from pinobs.observers import adaptive_fused, adaptive_learner, make_observer
from pinobs.observers.adaptive_blend import REJECTED_RUN, blend_inputs
from pinobs.observers.adaptive_fused import blame_of
from pinobs.observers.gating import GateState
from pinobs.simulation import Sensor
from pinobs.simulation.mismatch import mismatched_plant
from tests.conftest import cached_robot, varied_samples


def _outputs(ob, sim, *, varied: bool) -> list[np.ndarray]:
    """Every estimate's arrays, NIS and gate, and every 100th sample what the learner says."""
    ob.reset(sim.t[0], sim.q[0], None, sim.tau[0])
    if varied:
        samples = varied_samples(
            sim, outlier_at=700, outlier=lambda q: q + 0.5, missed=True, varied_tau=True
        )
    else:
        samples = ((k, sim.t[k], sim.q_meas[k], sim.tau[k]) for k in range(1, sim.t.size))
    out = []
    for k, t, q, tau in samples:
        e = ob.update(t, q, tau)
        out += [e.q, e.v, np.array([e.t, math.nan if e.nis is None else e.nis, e.gated])]
        if k % 100 == 0:
            d = ob.consistency().details
            keys = ("solves", "installs", "rows", "restarts", "inconclusive", "condition", "rank")
            out += [np.array([d[key] for key in keys], dtype=float), np.array(d["blend_weight"])]
            out += [ob.covariance(), ob.disturbance, np.array([d["regime"] == "learned"])]
    p = ob.parameters()
    buf = ob._state.learner.buf
    return [*out, p.values, p.std, ob.snapshot().offset, buf.rows[buf.start : buf.end]]


@pytest.mark.parametrize(
    ("robot_name", "sigma", "varied", "learning"),
    [
        ("ur5", 1e-4, False, "sync"),
        ("ur5", 1e-3, True, "sync"),
        ("ur5", 1e-4, True, "background"),
        ("panda", 1e-4, True, "sync"),
        ("panda", 1e-3, False, "background"),
    ],
)
def test_the_fused_update_gives_the_base_paths_bits_learning_included(
    robot_name: str, sigma: float, varied: bool, learning: str, monkeypatch
) -> None:
    """A UR5 or Panda whose truth has ±20 % links and a payload (learned models installed,
    their friction held as an input), plain or varied samples (dropped, strided, read-only, an
    outlier, missing torques, missed ticks); background learning joined (the test hook)."""
    robot = cached_robot(robot_name)
    plant = mismatched_plant(robot, "inertia20_payload", seed=0)
    sim = pinobs.simulate(
        robot, [], duration=1.6, sensor=Sensor(1000.0, sigma), seed=1, plant=plant
    )
    monkeypatch.setattr(adaptive_learner.Learner, "join", learning == "background")
    fused = make_observer("adaptive", robot, rate=1000.0, noise_std=sigma, learning=learning)
    base = make_observer("adaptive", robot, rate=1000.0, noise_std=sigma, learning=learning)
    assert fused._fused_path
    base._fused_path = False  # (the base's path: the step, the commit, after_commit)
    got, expected = _outputs(fused, sim, varied=varied), _outputs(base, sim, varied=varied)
    assert fused.consistency().details["installs"] >= 1  # learned models were installed
    assert len(got) == len(expected)
    for a, b in zip(got, expected, strict=True):
        assert np.array_equal(a, b, equal_nan=True)


def test_a_plain_sample_takes_the_fused_update(monkeypatch) -> None:
    """Every update with a sample on the interval but the first (the learner starts there), on
    a UR5 learning its model: 3 Python calls an update (tests/observers/test_update_path.py)."""
    robot = cached_robot("ur5")
    plant = mismatched_plant(robot, "inertia20_payload", seed=0)
    sim = pinobs.simulate(robot, [], duration=1.2, sensor=Sensor(1000.0, 1e-4), seed=1, plant=plant)
    taken = []
    fused_step = adaptive_fused.fused_step

    def counted(*args):
        step = fused_step(*args)
        taken.append(step is not None)
        return step

    monkeypatch.setattr(adaptive_fused, "fused_step", counted)
    ob = make_observer("adaptive", robot, rate=1000.0, noise_std=1e-4)
    ob.reset(sim.t[0], sim.q[0], None, sim.tau[0])
    for k in range(1, sim.t.size):
        ob.update(sim.t[k], sim.q_meas[k], sim.tau[k])
    assert len(taken) == sim.t.size - 1
    assert sum(taken) >= len(taken) - 10, taken.count(False)  # (a gated sample, an install)


@pytest.mark.parametrize(
    "level", [6.0, 12.0, 18.0, 24.0, 30.0, 100.0, 5.9, 0.0, -0.0, math.inf, math.nan, 1e308]
)
@pytest.mark.parametrize(("restarted", "rejected_run"), [(False, 0), (True, 0), (False, 4)])
def test_the_kernels_blame_is_blend_inputs(level: float, restarted: bool, rejected_run: int):
    """:func:`~pinobs.observers.adaptive_fused.blame_of` (Python's ``min``/``max`` written out)
    gives ``blend_inputs``' blame, to the bit, where the sample was let through."""
    from types import SimpleNamespace

    nv = 6
    gate = GateState(nis=1.0, gated=False, run=0, level=level, drift=None)
    ekf = SimpleNamespace(gate=gate, v=np.zeros(nv))
    model = SimpleNamespace(restarted=restarted, rejected_run=rejected_run)
    _, blame = blend_inputs(ekf, model, np.zeros(nv))  # type: ignore[arg-type]
    full = restarted or rejected_run >= REJECTED_RUN
    assert np.array_equal(np.float64(blame_of(level, nv, full)), np.float64(blame))
    assert math.copysign(1.0, blame_of(level, nv, full)) == math.copysign(1.0, blame)
