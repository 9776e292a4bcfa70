"""Start-up: ``import pinobs`` stays light (issues 18 and 39)."""

from __future__ import annotations

import subprocess
import sys

import pytest

from tests.conftest import last_line


def test_import_pinobs_imports_no_numba_scipy_linalg_or_meshcat() -> None:
    code = (
        "import sys, pinobs; "
        "print(sorted(m for m in ('numba', 'scipy.linalg', 'meshcat', 'matplotlib') "
        "if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_import_pinobs_cli_imports_no_plotting_playback_dataframes_or_dask() -> None:
    """Every command's parser is built at start-up; what a command needs beyond it is
    imported when it runs (``pinobs --help`` stays quick)."""
    heavy = ("numba", "scipy.linalg", "meshcat", "matplotlib", "pandas", "pyarrow", "dask", "rich")
    code = f"import sys, pinobs.cli; print(sorted(m for m in {heavy!r} if m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_import_pinobs_imports_no_layer_and_make_observer_only_its_family() -> None:
    """Issue 39: ``import pinobs`` imports neither pinocchio nor any layer (its public names
    are imported on first use); ``make_observer("fd")`` imports that family only, and no
    numba."""
    code = (
        "import sys, pinobs\n"
        "print(sorted(m for m in ('numba', 'pinocchio', 'scipy', 'pinobs.model') if m in sys.modules))\n"
        "pinobs.make_observer('fd', pinobs.load('cartpole'))\n"
        "print(sorted(m for m in sys.modules if m.startswith('pinobs.observers.')"
        " and m.rsplit('.', 1)[1] in {'kf', 'ekf', 'adaptive', 'riemannian', 'fd'}), "
        "'numba' in sys.modules)\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], check=True, capture_output=True, text=True
    ).stdout.splitlines()
    assert out == ["[]", "['pinobs.observers.fd'] False"]


def test_every_public_name_resolves_to_its_module_s_object() -> None:
    """The lazy ``pinobs.<name>`` (PEP 562) is the defining module's object, listed by
    ``dir``; an unknown name raises ``AttributeError`` naming it."""
    import importlib

    import pinobs

    for name in pinobs.__all__:
        value = getattr(pinobs, name)
        module = value.__module__ if hasattr(value, "__module__") else None
        assert module is not None and module.startswith("pinobs")
        assert getattr(importlib.import_module(module), name) is value
        assert name in dir(pinobs)
    with pytest.raises(AttributeError, match="no attribute 'nope'"):
        pinobs.nope  # noqa: B018


def test_adaptive_learning_and_inekf_reset_import_no_scipy_signal_ndimage_or_spatial() -> None:
    """Issue 39: ``adaptive``'s learner (made, then its first windows and first solve, on a
    UR5 at 1 kHz) and ``inekf``'s reset no longer import ``scipy.signal`` (0.45 s CPU),
    ``scipy.ndimage`` or ``scipy.spatial``: NumPy does their arithmetic, to the bit (tested
    in tests/model/test_identification.py and tests/observers/test_leg_contacts.py)."""
    code = (
        "import sys, numpy as np, pinobs\n"
        "robot = pinobs.load('ur5')\n"
        "obs = pinobs.make_observer('adaptive', robot, rate=1000.0, noise_std=1e-4)\n"
        "q0 = robot.neutral(); obs.reset(0.0, q0)\n"
        "for k in range(1, 700):\n"
        "    obs.update(k * 1e-3, q0 + 0.1 * np.sin(k * 1e-2 + np.arange(robot.nv)))\n"
        "assert obs.consistency().details['solves'] >= 1\n"
        "from pinobs.observers.inekf import InvariantEKF\n"
        "go1 = pinobs.load('go1')\n"
        "ekf = InvariantEKF(go1, ('FL_foot', 'FR_foot', 'RL_foot', 'RR_foot'))\n"
        "q = np.zeros(go1.nq); q[2] = 0.3; q[6] = 1.0\n"
        "gyro, acc = np.array([0.01, -0.02, 0.03]), np.array([0.1, 0.0, 9.81])\n"
        "ekf.reset(0.0, q, gyro=gyro, acc=acc, contacts=[True] * 4)\n"
        "ekf.update(1e-3, q, gyro, acc, [True] * 4)\n"
        "heavy = ('scipy.signal', 'scipy.ndimage', 'scipy.spatial', 'scipy.stats')\n"
        "print(sorted(m for m in heavy if m in sys.modules))\n"
    )
    assert last_line(code) == "[]"


def test_ekf_and_background_adaptive_run_without_scipy_linalg_in_the_loops_process() -> None:
    """Issue 39: ``scipy.linalg`` costs 0.15 s of CPU at import, and loads SciPy's OpenBLAS,
    whose worker thread then spins 0.1-0.2 s of CPU on the other core.  ``ekf`` on a UR5
    (``nv`` ≤ 12: its compiled Joseph update) imports LAPACK only where it needs it (past
    the kernels, or a covariance that is not positive definite); ``adaptive`` learning in
    the background imports it in its worker process only.  Made, then 300 updates."""
    code = (
        "import sys, numpy as np, pinobs\n"
        "if __name__ == '__main__':\n"
        "    robot = pinobs.load('ur5')\n"
        "    for opts in ({'name': 'ekf'}, {'name': 'adaptive', 'learning': 'background'}):\n"
        "        obs = pinobs.make_observer(**opts, robot=robot, rate=1000.0, noise_std=1e-4)\n"
        "        q0 = robot.neutral(); obs.reset(0.0, q0)\n"
        "        for k in range(1, 300):\n"
        "            obs.update(k * 1e-3, q0 + 0.1 * np.sin(k * 1e-2 + np.arange(robot.nv)))\n"
        "    print('scipy.linalg' in sys.modules)\n"
    )
    assert last_line(code) == "False"


def test_synchronous_adaptive_learns_without_scipy_linalg() -> None:
    """Issue 39: ``adaptive``'s synchronous learning (made, then its first windows and
    solves, on a UR5 at 1 kHz) imports no ``scipy.linalg`` (0.13 s of its construction's main
    thread, and SciPy's OpenBLAS, whose thread spun 0.09 s more): its pivoted QR is LAPACK's
    ``dgeqp3`` in NumPy's OpenBLAS, its Savitzky–Golay coefficients NumPy's ``lstsq``."""
    code = (
        "import sys, numpy as np, pinobs\n"
        "robot = pinobs.load('ur5')\n"
        "obs = pinobs.make_observer('adaptive', robot, rate=1000.0, noise_std=1e-4)\n"
        "q0 = robot.neutral(); obs.reset(0.0, q0)\n"
        "for k in range(1, 1100):\n"
        "    obs.update(k * 1e-3, q0 + 0.1 * np.sin(k * 1e-2 + np.arange(robot.nv)))\n"
        "print(obs.consistency().details['solves'] >= 2, 'scipy.linalg' in sys.modules)\n"
    )
    assert last_line(code) == "True False"


def test_warm_linear_algebra_imports_lapack_only_past_the_compiled_kernels() -> None:
    """A filter's constructor loads what its updates call: the compiled Joseph update for
    ``nv`` ≤ :data:`~pinobs.observers.linalg.KERNEL_MAX_NV`, LAPACK's ``dposv`` above."""
    code = (
        "import sys\n"
        "from pinobs.observers.linalg import KERNEL_MAX_NV, joseph_kernel, warm_linear_algebra\n"
        "warm_linear_algebra(KERNEL_MAX_NV)\n"
        "print(joseph_kernel.compiled is not None, 'scipy.linalg' in sys.modules)\n"
        "warm_linear_algebra(KERNEL_MAX_NV + 1)\n"
        "print('scipy.linalg' in sys.modules)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["True", "False", "True"]


def test_riemannian_made_a_second_time_imports_no_scipy_linalg() -> None:
    """Issue 39: ``riemannian``'s gains from the noise solve a Riccati equation with SciPy
    once; a later process takes the solution from the cache (:mod:`pinobs.observers.gain_cache`,
    the same bits) and imports no ``scipy.linalg`` (made, then 300 updates on a UR5)."""
    code = (
        "import sys, numpy as np, pinobs\n"
        "robot = pinobs.load('ur5')\n"
        "obs = pinobs.make_observer('riemannian', robot, rate=1000.0, noise_std=1e-4)\n"
        "q0 = robot.neutral(); obs.reset(0.0, q0)\n"
        "for k in range(1, 300):\n"
        "    obs.update(k * 1e-3, q0 + 0.1 * np.sin(k * 1e-2 + np.arange(robot.nv)))\n"
        "print('scipy.linalg' in sys.modules)\n"
    )
    assert last_line(code, runs=2) == "False"


def test_highgain_and_kalman_made_a_second_time_import_no_scipy_linalg() -> None:
    """Issue 39: ``highgain``'s default bandwidth (a Lyapunov equation) and exact holds at its
    regular intervals (``expm``) are computed with SciPy once; a later process takes them from
    the cache (:mod:`pinobs.observers.gain_cache`, the same bits) and imports no
    ``scipy.linalg``.  ``highgain`` and ``kalman`` on a UR5, made, then 1000 updates at
    ±50 µs-jittered stamps (their intervals off the table: no ``expm``) that import no
    module."""
    code = (
        "import sys, numpy as np, pinobs\n"
        "robot = pinobs.load('ur5')\n"
        "rng = np.random.default_rng(0)\n"
        "for name in ('highgain', 'kalman'):\n"
        "    obs = pinobs.make_observer(name, robot, rate=1000.0, noise_std=1e-4)\n"
        "    q0 = robot.neutral(); obs.reset(0.0, q0)\n"
        "    obs.update(1e-3, q0)\n"
        "    before = set(sys.modules)\n"
        "    for k in range(2, 1000):\n"
        "        t = k * 1e-3 + rng.uniform(-5e-5, 5e-5)\n"
        "        obs.update(t, q0 + 0.1 * np.sin(k * 1e-2 + np.arange(robot.nv)))\n"
        "    assert set(sys.modules) == before, sorted(set(sys.modules) - before)\n"
        "print('scipy.linalg' in sys.modules)\n"
    )
    assert last_line(code, runs=2) == "False"


def test_inekf_on_go1_imports_no_scipy_linalg() -> None:
    """Issue 39: the invariant EKF's compiled kernels multiply their 3 × 3 matrices in loops,
    not by numba's ``@`` (which calls SciPy's BLAS: ``scipy.linalg`` imported when the
    kernels load, 0.15-0.2 s of CPU in ``make_observer``), and the rolling feet's kernels
    get the layout of their loaded signature (another one loads with numba's full set-up,
    which imports ``scipy.linalg``).  go1 without and with rolling feet (``rolling_lift``,
    the foot gate): made, reset, then 50 updates, in a second process (the first may
    compile)."""
    code = (
        "import sys, numpy as np, pinobs\n"
        "from pinobs.observers.inekf import InvariantEKF\n"
        "go1 = pinobs.load('go1')\n"
        "feet = ('FL_foot', 'FR_foot', 'RL_foot', 'RR_foot')\n"
        "q = np.zeros(go1.nq); q[2] = 0.3; q[6] = 1.0\n"
        "gyro, acc = np.array([0.01, -0.02, 0.03]), np.array([0.1, 0.0, 9.81])\n"
        "for opts in ({}, {'foot_radius': 0.02, 'rolling_lift': True, 'foot_gate': 1e-3}):\n"
        "    ekf = InvariantEKF(go1, feet, **opts)\n"
        "    ekf.reset(0.0, q, gyro=gyro, acc=acc, contacts=[True] * 4)\n"
        "    for k in range(1, 51):\n"
        "        ekf.update(k * 1e-3, q, gyro, acc, [True] * 4)\n"
        "print('scipy.linalg' in sys.modules)\n"
    )
    assert last_line(code, runs=2) == "False"


@pytest.mark.parametrize("name", ["ekf", "riemannian", "liegroup"])
def test_no_update_imports_a_module_on_a_lie_group_robot(name: str) -> None:
    """Issue 39: the RK4 stages on Lie groups solve with LAPACK's ``dgesv``
    (:meth:`~pinobs.model.Robot.integrate_jacobian_solve`), imported from ``scipy.linalg``
    on first use: in the first or second update (0.16-0.34 s) unless the constructor loads
    it (``LieRK4.build``, ``liegroup``).  A spherical top: made, reset, then 50 updates
    that import nothing."""
    code = (
        "import sys, numpy as np, pinobs\n"
        "robot = pinobs.load('top')\n"
        f"obs = pinobs.make_observer({name!r}, robot, rate=1000.0, noise_std=1e-4)\n"
        "q0 = robot.neutral(); obs.reset(0.0, q0)\n"
        "before = set(sys.modules)\n"
        "for k in range(1, 51):\n"
        "    obs.update(k * 1e-3, robot.integrate(q0, 1e-3 * np.sin(k * 1e-2 + np.arange(3))))\n"
        "print(sorted(set(sys.modules) - before))\n"
    )
    assert last_line(code) == "[]"


def test_identification_names_resolve_on_first_use_to_their_modules_objects() -> None:
    """Issue 39: ``pinobs.model.identification`` imports its modules when a name is first
    asked for (PEP 562), so ``adaptive``'s learner loads the regressor, solve and smoothing
    only; every public name is its module's object and listed by ``dir``."""
    import importlib

    from pinobs.model import identification

    for name, module in identification._LAZY.items():
        value = getattr(identification, name)
        source = importlib.import_module(f"pinobs.model.identification.{module}")
        assert getattr(source, name) is value
        assert name in dir(identification)
    assert set(identification.__all__) <= set(identification._LAZY)
    with pytest.raises(AttributeError, match="no attribute 'nope'"):
        identification.nope  # noqa: B018
    code = (
        "import sys, pinobs.model.identification\n"
        "print(sorted(m for m in sys.modules if m.startswith('pinobs.model.identification.')))\n"
    )
    assert last_line(code) == "[]"
