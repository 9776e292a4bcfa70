"""One failing observer does not take the others' results with it."""

from __future__ import annotations

import numpy as np

import pinobs


def test_simulate_reports_a_failing_observer_and_keeps_the_others() -> None:
    robot = pinobs.load("cartpole")
    good = pinobs.make_observer("kf", robot, rate=1000.0)
    bad = pinobs.make_observer("kf", robot, rate=1000.0)
    calls = {"n": 0}
    step = bad.step

    def failing_step(*args):  # a singular matrix at the 50th update
        calls["n"] += 1
        if calls["n"] == 50:
            raise np.linalg.LinAlgError("Singular matrix")
        return step(*args)

    bad.step = failing_step  # type: ignore[method-assign]
    res = pinobs.simulate(robot, {"good": good, "bad": bad}, duration=0.2, seed=0)
    assert "LinAlgError at t = 0.05 s: Singular matrix" in res.meta["failures"]["bad"]
    assert res.trace("bad").diverged_at == 0.05
    assert np.isnan(res.trace("bad").v[50:]).all() and np.isfinite(res.trace("bad").v[:50]).all()
    assert np.isfinite(res.trace("good").v).all()
    assert "good" not in res.meta["failures"]
