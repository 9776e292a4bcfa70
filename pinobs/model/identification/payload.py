"""A payload's ten inertial parameters on a calibrated robot (:class:`PayloadRegressor`,
:func:`identify_payload`; Atkeson, An & Hollerbach 1986)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike, NDArray

from pinobs.errors import IdentificationError, OptionError
from pinobs.model.identification.diagnostics import (
    check_zero_torques,
    fit_report,
    fit_warnings,
)
from pinobs.model.identification.leastsquares import MAX_CONDITION, Solution, solve
from pinobs.model.identification.regressor import (
    SUFFIXES,
    MomentumRegressor,
    check_options,
    check_torque,
    check_weighting,
    excluded_coordinates,
)
from pinobs.model.identification.result import Identification, ParameterSet, Report
from pinobs.model.identification.rows import (
    fit_rows,
    holdout_in_newton_metres,
    holdout_rows,
    read_fit_log,
)
from pinobs.model.robot import Robot, Vector

__all__ = ["PRIOR_PAYLOAD_LENGTH", "PRIOR_PAYLOAD_MASS", "PayloadRegressor", "identify_payload"]


#: Prior standard deviations of a payload's parameters (:class:`PayloadRegressor`): its mass
#: in units of the robot's total mass, its first and second moments as that mass at
#: :data:`PRIOR_PAYLOAD_LENGTH` from the frame.  The prior mean is no payload (all zero).
PRIOR_PAYLOAD_MASS, PRIOR_PAYLOAD_LENGTH = 1.0, 0.25


class PayloadRegressor:
    """The momentum-form rows of a payload's ten inertial parameters ``φ`` on an otherwise
    known (calibrated) robot.

    ``φ`` (``m, m·c, I`` at the frame's origin, in the frame's axes, Pinocchio's
    ``toDynamicParameters`` order) adds ``T φ`` to the parameters of the joint carrying the
    frame, ``T`` the (linear) action of the frame's placement on dynamic parameters
    (:meth:`placement_map`).  With ``A`` and ``y`` the rows of :class:`MomentumRegressor` on
    the robot (its friction included when on; its armature known) and ``θ_c`` its
    parameters::

        A_p = A[:, π_j] T,    y_p = y − A θ_c

    (a load fixed to a body changes nothing else: Atkeson, An & Hollerbach 1986, "Estimation
    of inertial parameters of manipulator loads and links", §3).

    Args:
        robot: the calibrated robot (taken as exact).
        frame: a frame (body, link or tool frame) of the robot, moved by a joint.
        weighting, exclude: as :class:`MomentumRegressor`'s.
    """

    n_joint = 0
    friction = False
    friction_terms: tuple[str, ...] = ()
    offset = False
    armature = False

    def __init__(
        self, robot: Robot, frame: str, *, weighting: str = "inertia", exclude: Sequence[str] = ()
    ) -> None:
        model = robot.model
        if not isinstance(frame, str) or not model.existFrame(frame):
            bodies = [str(f.name) for f in model.frames if f.type == pin.FrameType.BODY]
            raise OptionError(
                f"payload={frame!r} is not a frame of {robot.name!r}; its bodies: "
                + ", ".join(bodies)
            )
        f = model.frames[model.getFrameId(frame)]
        if f.parentJoint == 0:
            raise OptionError(
                f"payload={frame!r} is fixed to the world: a load there moves nothing; give a "
                "frame moved by a joint (the end effector's)"
            )
        self.robot = robot
        self.frame = frame
        self.joint = int(f.parentJoint)
        self.placement = f.placement
        self.weighting = weighting
        self.base = MomentumRegressor(
            robot,
            friction=robot.friction,
            offset=False,
            armature=False,
            weighting=weighting,
            exclude=exclude,
        )
        self._theta = self.base.nominal()
        self._cols = slice(10 * (self.joint - 1), 10 * self.joint)
        self._map = self.placement_map(self.placement)
        self.n_inertial = 10
        self.names = tuple(f"payload.{s_}" for s_ in SUFFIXES)
        self.armature_slice = slice(10, 10)

    @staticmethod
    def placement_map(placement: pin.SE3) -> Vector:
        """``T`` (10 × 10) with ``(X·I)`` 's dynamic parameters ``= T π(I)``, ``X`` the
        placement: the action is linear in ``(m, m·c, I_origin)``, so its columns are
        differences of the action on an inertia and on that inertia plus a unit step."""
        ref = pin.Inertia(1.0, np.zeros(3), np.eye(3))
        pi0 = ref.toDynamicParameters()
        out0 = placement.act(ref).toDynamicParameters()
        cols = [
            placement.act(pin.Inertia.FromDynamicParameters(pi0 + e)).toDynamicParameters() - out0
            for e in np.eye(10)
        ]
        return np.array(cols).T

    @property
    def size(self) -> int:
        """Number of parameters (10)."""
        return 10

    def nominal(self) -> Vector:
        """The prior mean: no payload."""
        return np.zeros(10)

    def prior_std(self) -> Vector:
        """:data:`PRIOR_PAYLOAD_MASS` of the robot's mass, at :data:`PRIOR_PAYLOAD_LENGTH`."""
        model = self.robot.model
        m = PRIOR_PAYLOAD_MASS * max(sum(float(i.mass) for i in model.inertias), 1e-3)
        length = PRIOR_PAYLOAD_LENGTH
        return np.array([m, *(3 * [m * length]), *(6 * [m * length**2])])

    def with_parameters(self, phi: ArrayLike, *, name: str | None = None) -> Robot:
        """The robot carrying the payload ``φ`` (added to its joint's inertia)."""
        phi = np.asarray(phi, dtype=float)
        model = self.robot.model.copy()
        pi = model.inertias[self.joint].toDynamicParameters() + self._map @ phi
        model.inertias[self.joint] = pin.Inertia.FromDynamicParameters(pi)
        return self.robot.with_model(
            model, name=name or f"{self.robot.name}+payload", friction=self.robot.friction
        )

    def system(
        self,
        t: Vector,
        q: Vector,
        v: Vector,
        tau: Vector,
        *,
        window: int,
        stride: int = 1,
        weight_robot: Robot | None = None,
        torque: str = "held",
    ) -> tuple[Vector, Vector]:
        """``(A_p, y_p)`` of :meth:`MomentumRegressor.system`'s windows (class docstring)."""
        A, y = self.base.system(
            t, q, v, tau, window=window, stride=stride, weight_robot=weight_robot, torque=torque
        )
        return A[:, self._cols] @ self._map, y - A @ self._theta

    def window_ends(self, t: Vector, window: int, stride: int = 1) -> list[float]:
        """As :meth:`MomentumRegressor.window_ends`."""
        return self.base.window_ends(t, window, stride)


def identify_payload(
    robot: Robot,
    log: Any,
    frame: str,
    *,
    holdout: float = 0.2,
    window: float = 0.1,
    path: tuple[ArrayLike, ArrayLike] | None = None,
    torque: str = "held",
    exclude: Sequence[str] = (),
    weighting: str = "inertia",
) -> Identification:
    """The ten inertial parameters of a load attached to ``frame`` of a calibrated ``robot``
    (:class:`PayloadRegressor`), everything else fixed; physically consistent (the load's
    pseudo-inertia ``⪰ 0``, Wensing et al. 2017, by :func:`solve`).

    Rows weighted as :func:`identify`'s (by default through ``M⁻¹``; ``weighting="torque"``:
    each torque channel in N·m by its own residual scale); the held-out report is in N·m
    either way.  The result's ``robot`` carries the payload; ``report["payload"]`` gives
    its mass [kg], centre of mass [m, in ``frame``] and rotational inertia about it
    [kg·m², in ``frame``'s axes]; ``report["holdout_torque_before"]`` is the robot without
    it.  Other arguments and report keys: :func:`identify`'s.
    """
    check_options(False, False, False, holdout, window, MAX_CONDITION)
    check_torque(torque)
    check_weighting(weighting)
    excluded = excluded_coordinates(robot, exclude)
    reg = PayloadRegressor(robot, frame, weighting=weighting, exclude=exclude)
    t, q, tau, filled, est = read_fit_log(robot, log, path)
    check_zero_torques(robot, tau, excluded)
    finite = np.isfinite(t)
    if finite.sum() < 2:
        raise IdentificationError("the log has fewer than two finite times")
    t_start, t_end = float(np.min(t[finite])), float(np.max(t[finite]))
    split = t_end - holdout * (t_end - t_start)
    fit = t <= split
    options: dict[str, Any] = {"window": window, "path": est, "torque": torque}
    A, y, _ = fit_rows(reg, (t, q, tau), fit, **options)
    nv = robot.nv
    channel = np.tile(np.arange(nv), A.shape[0] // nv)
    used = ~np.isin(channel, excluded)
    sol = solve(reg, A[used], y[used], channel=channel[used] if weighting == "torque" else None)
    held = holdout_rows(reg, (t, q, tau), ~fit, holdout=holdout, **options)
    held_nm = holdout_in_newton_metres(
        reg,
        lambda: PayloadRegressor(robot, frame, weighting="torque", exclude=exclude),
        held,
        (t, q, tau),
        ~fit,
        **options,
    )
    report = _payload_report(
        reg,
        sol,
        {"fit": (A, y), "held": held, "held_nm": held_nm},
        excluded,
        channel[used],
        {"torque": torque, "fit_end": split, "filled_rows": filled},
    )
    report["warnings"] = fit_warnings(report)
    if sol.condition > MAX_CONDITION:
        report["warnings"].append(
            f"the payload's parameters are poorly excited: condition number "
            f"{sol.condition:.3g} > {MAX_CONDITION:.3g}; those not excited stay near zero"
        )
    zero = np.zeros(10)
    params = ParameterSet(
        names=reg.names, values=sol.theta, std=sol.std, nominal=zero, excited=sol.excited
    )
    return Identification(
        robot=reg.with_parameters(sol.theta, name=f"{robot.name}+payload"),
        parameters=params,
        offset=np.zeros(nv),
        report=report,
        regressor=reg.base,
    )


def _payload_report(
    reg: PayloadRegressor,
    sol: Solution,
    rows: dict[str, tuple[Vector, Vector]],
    excluded: NDArray[np.intp],
    channel: NDArray[np.intp],
    log: dict[str, Any],
) -> Report:
    """:func:`identify_payload`'s report (its ``warnings`` apart; :func:`fit_report`):
    ``rows`` the fitted (``"fit"``), held-out (``"held"``) and held-out N·m (``"held_nm"``)
    rows, ``channel`` the fitted rows' channels, ``log`` its ``torque``, ``fit_end`` and
    ``filled_rows``."""
    nv, phi = reg.robot.nv, sol.theta
    inertia = pin.Inertia.FromDynamicParameters(phi) if phi[0] > 0 else None
    payload = {
        "frame": reg.frame,
        "mass": float(phi[0]),
        "com": [math.nan] * 3 if inertia is None else inertia.lever.tolist(),
        "inertia": [[math.nan] * 3] * 3 if inertia is None else inertia.inertia.tolist(),
        "mass_std": float(sol.std[0]),
    }
    # (no unexplained shares here: the rows' torque side is what the calibrated robot leaves,
    # whose share the payload explains says nothing of the model's)
    diagnosed = {
        "unexplained": [math.nan] * nv,
        "unexplained_floor": [math.nan] * nv,
        "outlier_windows": [],
    }
    zero = np.zeros(10)
    return fit_report(
        reg, sol, rows, zero, excluded, channel, log, diagnosed, moved=[], payload=payload
    )
