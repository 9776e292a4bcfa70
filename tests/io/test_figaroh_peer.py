"""``benchmarks/figaroh_peer.py``'s FIGAROH driving, on torques made from a known model:
skipped without FIGAROH (``pip install 'pinobs[peers]'``)."""

from __future__ import annotations

import importlib.util
import warnings
from pathlib import Path
from types import ModuleType

import numpy as np
import pinocchio as pin
import pytest

import pinobs
from tests.io.test_real_data import bench_module

VS = 0.01  # [rad/s] the benchmark's tanh velocity (pinobs's COULOMB_SMOOTHING_VELOCITY)
LEGACY_CONFIG = """\
identification:
  robot_params:
    - fv: [0, 0, 0, 0, 0, 0]
      fs: [0, 0, 0, 0, 0, 0]
      Ia: [0, 0, 0, 0, 0, 0]
      offset: [0, 0, 0, 0, 0, 0]
  problem_params:
    - is_joint_torques: True
      has_friction: True
      has_joint_offset: True
      has_actuator_inertia: True
  processing_params:
    - ts: 0.002
"""


def _peer() -> ModuleType:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # ndcurves' converters registered twice on import
        if importlib.util.find_spec("figaroh") is None:
            pytest.skip("FIGAROH is not installed (pip install 'pinobs[peers]')")
        import figaroh.identification.base_identification  # noqa: F401
    return bench_module("figaroh_peer")


def _known_torques(model: pin.Model, t: np.ndarray):
    """A smooth trajectory and its torques: ``τ = RNEA + F_v v + F_c tanh(v / VS) + I_a a +
    b`` with fixed per-joint values (the columns FIGAROH's model has, Coulomb as tanh)."""
    n = model.nv
    w = 2 * np.pi * np.array([0.3, 0.5, 0.7, 0.4, 0.6, 0.8])[:n]
    amp = 0.8 * np.ones(n)
    q = amp * np.sin(np.outer(t, w))
    v = amp * w * np.cos(np.outer(t, w))
    a = -amp * w**2 * np.sin(np.outer(t, w))
    data = model.createData()
    fv, fc, ia, off = (np.linspace(lo, hi, n) for lo, hi in ((1, 3), (2, 5), (0.1, 0.4), (-1, 1)))
    tau = np.array([pin.rnea(model, data, q[k], v[k], a[k]) for k in range(len(t))])
    tau += fv * v + fc * np.tanh(v / VS) + ia * a + off
    return q, v, a, tau


@pytest.mark.parametrize(("kind", "exact"), [("tanh", True), ("sign", False)])
def test_fed_figaroh_predicts_held_out_torques_of_its_own_model_class(
    tmp_path: Path, kind: str, exact: bool
) -> None:
    """FIGAROH fed the rows (fit on 80 %, validate on 20 %) predicts the held-out torques
    of a model in its own class exactly with the tanh column, not with its sign one."""
    peer = _peer()
    robot = pinobs.load("ur5")
    t = np.arange(0.0, 5.0, 0.01)
    q, v, a, tau = _known_torques(robot.model, t)
    fit = t <= 4.0
    sets = {rows: (t[m], q[m], v[m], a[m], tau[m]) for rows, m in ((None, fit), ("held_out", ~fit))}
    legacy = tmp_path / "legacy.yaml"
    legacy.write_text(LEGACY_CONFIG)
    config = peer.unified_config(legacy, "ur5", tmp_path)
    joints = list(robot.joint_names)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        out = peer.run_fed(pin.RobotWrapper(robot.model.copy()), config, sets, joints, joints, kind)
    scale = np.sqrt(np.mean(tau[~fit] ** 2, axis=0))
    rel = np.asarray(out["held_out"]) / scale
    np.testing.assert_allclose(out["held_out"], out["figaroh_rmse_identified"], rtol=1e-9)
    if exact:
        assert rel.max() < 1e-6
    else:
        assert rel.max() > 1e-3
