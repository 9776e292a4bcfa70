"""The identification's report: typed fields that read and write as a mapping (issue 37)."""

from __future__ import annotations

import dataclasses
import pickle

import numpy as np
import pytest

import pinobs
from pinobs.model.identification import Report, identify
from pinobs.simulation import Sensor
from tests.conftest import planar_3r_truth

#: the report's keys in their order, friction identified, no payload
KEYS = [f.name for f in dataclasses.fields(Report) if f.name not in ("payload", "extra")]


@pytest.fixture(scope="module")
def ident() -> pinobs.model.identification.Identification:
    robot = pinobs.load("planar_3r")
    res = pinobs.simulate(
        robot,
        [],
        duration=3.0,
        sensor=Sensor(rate=1000.0, noise_std=1e-5),
        seed=1,
        plant=planar_3r_truth(robot),
    )
    return identify(robot, res)


def test_report_keys_are_its_fields_in_order_and_read_as_attributes(ident) -> None:
    rep = ident.report
    assert isinstance(rep, Report)
    order = [k for k in KEYS if k not in ("friction_law", "warnings")]
    assert list(rep) == [*order, "friction_law", "warnings"]
    for key in rep:
        assert rep[key] is getattr(rep, key)
    assert "payload" not in rep and rep.get("payload") is None
    with pytest.raises(KeyError):
        rep["payload"]
    assert rep["rows"] == ident.report.rows > 0
    assert dict(rep) == {k: getattr(rep, k) for k in rep}


def test_report_keeps_keys_set_after_the_fit_in_order(ident) -> None:
    rep = dataclasses.replace(ident.report, extra={})
    rep["observer_options"] = {}  # a field: set in place, its position kept
    assert rep.observer_options == {} and list(rep).index("observer_options") < len(KEYS)
    rep["velocities"] = "savgol"
    rep["noise_std"] = 1e-4
    assert list(rep)[-2:] == ["velocities", "noise_std"] and rep.extra["noise_std"] == 1e-4
    del rep["velocities"]
    assert "velocities" not in rep and len(rep) == len(KEYS) + 1
    with pytest.raises(TypeError, match="rows"):
        del rep["rows"]
    del rep["friction_law"]
    assert "friction_law" not in rep and rep.friction_law is None
    back = pickle.loads(pickle.dumps(rep))
    assert repr(dict(back)) == repr(dict(rep))  # (NaN != NaN: compared as text)


def test_payload_report_starts_with_the_payload() -> None:
    robot = pinobs.load("planar_3r")
    truth = planar_3r_truth(robot)
    res = pinobs.simulate(
        robot, [], duration=3.0, sensor=Sensor(rate=1000.0, noise_std=1e-5), seed=2, plant=truth
    )
    frame = robot.model.frames[-1].name
    rep = identify(robot, res, payload=frame).report
    assert next(iter(rep)) == "payload" and "friction_law" not in rep
    assert rep["payload"]["frame"] == frame and np.isfinite(rep.payload["mass_std"])
