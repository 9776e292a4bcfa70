"""Every code block of the README and the docs runs (issue 37).

Each fenced block of ``README.md`` and ``docs/**/*.md`` is one test, its id
``page:line`` (the line of its opening fence):

- ``python``: executed as a script (``__name__ == "__main__"``) in a temporary folder,
  its output compared with the ``text`` block that follows it when the prose between
  says it ``prints`` it.  A block that reads a file the user has is given one named as
  in the block, made by :data:`FIXTURES` (small simulated logs).
- ``bash``: each command (``&&`` and line continuations split, comments dropped) is
  checked: ``pinobs ...`` is parsed by the command's own parser (a wrong flag fails),
  then run in process when cheap (:data:`RUN`); ``pip install`` names only extras of
  ``pyproject.toml``; ``python SCRIPT`` names a script that exists and takes every
  ``--flag`` given, and says in :data:`NOT_RUN` why it is not run (each takes minutes, or
  rewrites committed results); ``python -m pytest`` is this suite (not run).
- ``text``: not code; each is the output of the block before it (compared) or listed in
  :data:`TEXT` with the test that checks it.

Blocks slower than about 5 s run only with ``-m slow`` (:data:`SLOW`); blocks that
need something this machine may lack skip, saying what (:data:`NEEDS`).
"""

from __future__ import annotations

import argparse
import ast
import contextlib
import importlib
import importlib.util
import io
import re
import shlex
import shutil
import textwrap
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import pinobs
from pinobs.cli import _parser, main

ROOT = Path(__file__).resolve().parents[1]
FENCE = re.compile(r"^([ \t]*)```(\w*)[ \t]*$")


@dataclass(frozen=True)
class Block:
    """A fenced block: its page, the line of its opening fence, its language, its code
    (dedented: a block inside a list is indented) and the prose after it up to the next
    block."""

    page: str
    line: int
    lang: str
    code: str
    after: str

    @property
    def id(self) -> str:
        return f"{self.page}:{self.line}"


def _blocks_of(path: Path) -> list[Block]:
    lines = path.read_text().splitlines()
    found: list[tuple[int, str, str, int]] = []  # start, lang, code, end
    i = 0
    while i < len(lines):
        m = FENCE.match(lines[i])
        if m is None:
            i += 1
            continue
        j = i + 1
        while not re.match(r"^[ \t]*```[ \t]*$", lines[j]):
            j += 1
        code = textwrap.dedent("\n".join(lines[i + 1 : j]) + "\n")
        found.append((i, m.group(2), code, j))
        i = j + 1
    page = str(path.relative_to(ROOT))
    return [
        Block(
            page,
            start + 1,
            lang,
            code,
            "\n".join(lines[end + 1 : found[k + 1][0] if k + 1 < len(found) else len(lines)]),
        )
        for k, (start, lang, code, end) in enumerate(found)
    ]


@cache
def blocks() -> tuple[Block, ...]:
    pages = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
    return tuple(b for p in pages for b in _blocks_of(p))


def _of(lang: str) -> list[Block]:
    return [b for b in blocks() if b.lang == lang]


def _output_of(block: Block) -> Block | None:
    """The ``text`` block right after ``block`` when the prose between says it prints it."""
    rest = blocks()[blocks().index(block) + 1 :]
    if rest and rest[0].page == block.page and rest[0].lang == "text":
        if re.fullmatch(r"\s*prints[^\n]*\s*", block.after):
            return rest[0]
    return None


#: Blocks (by page and a line of their code) slower than about 5 s: run with ``-m slow``
#: (times measured on a shared 2-core machine, load average 8-11).
SLOW: dict[tuple[str, str], str] = {
    ("docs/guides/learning.md", "ident = pinobs.identify(robot, log)"): "identification: 20 s",
    ("docs/guides/recorded-logs.md", "table = estimate_logs("): "a local Dask cluster: 28 s",
    ("README.md", "pinobs demo"): "every observer on two robots: 33-48 s",
    ("docs/benchmarks/index.md", "pinobs bench --quick"): "the quick benchmark: 71-171 s",
}

#: Blocks that need what this machine may not have: the block's line, and a check giving
#: the reason to skip (None: run).
NEEDS: dict[tuple[str, str], Callable[[], str | None]] = {
    ("docs/guides/scale-out.md", "from dask_jobqueue import SLURMCluster"): lambda: (
        None
        if importlib.util.find_spec("dask_jobqueue") and shutil.which("sbatch")
        else "needs a Slurm cluster (dask_jobqueue and sbatch)"
    ),
}

#: ``text`` blocks that are not the output of the block before them, and what checks them.
TEXT: dict[tuple[str, str], str] = {
    ("docs/guides/cli.md", "pinobs list"): (
        "the synopsis: tests/test_docs.py::"
        "test_command_line_page_names_every_option_of_every_command_and_no_other"
    ),
}

#: Scripts named in the docs that are never run here, and why.
NOT_RUN: dict[str, str] = {
    "benchmarks/run_bench.py": "writes the committed benchmarks/results.{md,json} (~2 min)",
    "benchmarks/learning.py": "writes the committed benchmarks/learning.{md,json}",
    "benchmarks/real_logs.py": "writes the committed benchmarks/real_logs.{md,json} (~12 min);"
    " its --quick run takes 337 s of CPU, over what CI's budget leaves",
    "benchmarks/never_behind_real.py": "needs the shared real logs and minutes",
    "benchmarks/real_logs_bound.py": "needs the shared real logs and minutes",
    "benchmarks/tx40_friction.py": "needs the shared TX40 log; writes the committed benchmarks/tx40_friction.md (~2-6 min)",
    "benchmarks/friction_hysteresis.py": "needs the shared real logs; writes the committed "
    "benchmarks/friction_hysteresis.md (~2 min)",
    "benchmarks/real_ekf_phases.py": "needs the shared UR10e logs; writes the committed "
    "benchmarks/real_ekf_phases.{md,json} (~3 min)",
    "benchmarks/never_behind_sim.py": "minutes of simulations",
    "benchmarks/never_behind_weights.py": "needs the shared UR10e logs; writes the committed "
    "benchmarks/never_behind_weights.md (~5 min)",
    "benchmarks/real_riemannian.py": "needs the shared real logs; writes the committed "
    "benchmarks/real_riemannian.json (~4 min)",
    "benchmarks/never_behind_cost.py": "a timing benchmark",
    "benchmarks/never_behind_exact.py": "240 runs of simulations (~5 min)",
    "benchmarks/drive_gains.py": "needs the shared real logs; writes the committed "
    "benchmarks/drive_gains.{md,json} (~10 min)",
    "benchmarks/figaroh_peer.py": "needs FIGAROH and the shared real logs; writes the "
    "committed benchmarks/figaroh_peer.{md,json} (~4 min)",
    "benchmarks/figaroh_gap.py": "needs FIGAROH and the shared TIAGo log; writes the "
    "committed benchmarks/figaroh_gap.{md,json} (~20 min)",
    "benchmarks/legged_real_innovations.py": "needs the shared Go1 log; writes the committed "
    "benchmarks/legged_real_innovations.md (~30 s)",
    "benchmarks/talos_imu_link.py": "MuJoCo TALOS with its IMU on imu_link and on the root "
    "through legged_run, several minutes; writes the committed benchmarks/talos_imu_link.md",
    "benchmarks/legged_adapt_noise.py": "MuJoCo go1 through legged_run and the shared Go1 log, "
    "~25 min; writes the committed benchmarks/legged_adapt_noise.md",
    "benchmarks/legged_coverage.py": "MuJoCo go1 trotting through both filters, seeds 0-2, "
    "~1 min; writes the committed benchmarks/legged_coverage.md",
    "benchmarks/legged_slip_axes.py": "MuJoCo go1 through legged_run, 77 runs; writes the "
    "committed benchmarks/legged_slip_axes.md (~20 min)",
}


#: ``pinobs`` commands run for real in the default run (cheap on the fixtures); the
#: others are parsed, and run only with ``-m slow`` when listed in :data:`SLOW`.
RUN = {"estimate"}


def _match(table: dict[tuple[str, str], Any], block: Block) -> Any:
    return next(
        (v for (page, line), v in table.items() if page == block.page and line in block.code),
        None,
    )


def test_every_entry_of_the_tables_names_one_block() -> None:
    for table in (SLOW, NEEDS, TEXT):
        for page, line in table:
            hits = [b for b in blocks() if b.page == page and line in b.code]
            assert len(hits) == 1, f"{page}: {line!r} is in {len(hits)} blocks"


def test_every_block_is_fenced_python_bash_or_text() -> None:
    assert len(blocks()) >= 20
    odd = [b.id for b in blocks() if b.lang not in ("python", "bash", "text")]
    assert not odd, f"fence these as python, bash or text: {odd}"


def test_every_text_block_is_output_checked_or_listed() -> None:
    outputs = {o.id for b in _of("python") if (o := _output_of(b)) is not None}
    for b in _of("text"):
        assert b.id in outputs or _match(TEXT, b), (
            f"{b.id}: a text block that no test checks; code goes in a python or bash block"
        )


def _parses(code: str) -> bool:
    try:
        ast.parse(code)
    except SyntaxError:
        return False
    return True


def test_no_text_block_is_python() -> None:
    python = [b.id for b in _of("text") if _parses(b.code)]
    assert not python, f"{python} parse as Python: fence them as python"


# ----------------------------------------------------------------- the files blocks read


def _simulated(robot_name: str, duration: float, rate: float = 1000.0, **load: Any):
    robot = pinobs.load(robot_name, **load)
    sensor = pinobs.Sensor(rate=rate, noise_std=1e-4)
    return robot, pinobs.simulate(robot, [], duration=duration, sensor=sensor, seed=0)


@cache
def _ur5_log() -> tuple[pinobs.Robot, Any]:
    return _simulated("ur5", 1.0)


def _ur5_csv(path: Path) -> None:
    _, r = _ur5_log()
    pinobs.io.write_log(path, r.t, r.q_meas, r.tau)


def _ur5_parquet(path: Path) -> None:
    pd = pytest.importorskip("pandas")
    _, r = _ur5_log()
    cols = {"t": r.t} | {f"q{i}": r.q_meas[:, i] for i in range(r.q_meas.shape[1])}
    cols |= {f"tau{i}": r.tau[:, i] for i in range(r.tau.shape[1])}
    pd.DataFrame(cols).to_parquet(path)


def _logs_folder(path: Path) -> None:
    path.mkdir()
    for name in ("a.csv", "b.csv"):
        _ur5_csv(path / name)


def _excitation(path: Path) -> None:
    _, r = _simulated("ur5", 6.0, rate=500.0)
    pinobs.io.write_log(path, r.t, r.q_meas, r.tau)


def _motors(path: Path) -> None:
    """The UR5 log on the motor side of the guide's drives: ``θ_m = T (q − q₀)`` and
    currents ``i = T⁻ᵀ τ / k``."""
    pd = pytest.importorskip("pandas")
    robot, r = _ur5_log()
    ns = _exec_prefix(
        "docs/guides/recorded-logs.md", "drives = pinobs.io.Drives", "drives = pinobs.io.Drives"
    )
    t_mat, k, q0 = np.asarray(ns["T"]), np.asarray(ns["k"]), np.asarray(ns["q0"])
    theta = (r.q_meas - q0) @ t_mat.T
    current = np.linalg.solve(t_mat.T, r.tau.T).T / k
    names = robot.joint_names
    cols = {"t": r.t} | {f"qm.{n}": theta[:, i] for i, n in enumerate(names)}
    cols |= {f"i.{n}": current[:, i] for i, n in enumerate(names)}
    pd.DataFrame(cols).to_csv(path, index=False)


def _arm(path: Path) -> None:
    _, r = _simulated("panda", 0.5, lock=["panda_finger_joint1", "panda_finger_joint2"])
    pinobs.io.write_log(path, r.t, r.q_meas, r.tau)


def _go1(path: Path) -> None:
    """Go1 standing 0.3 s in MuJoCo: IMU, joints and foot forces (no truth, no contact
    flags: the contacts come from the forces)."""
    pytest.importorskip("mujoco")
    pd = pytest.importorskip("pandas")
    from pinobs.simulation.legged import simulate_legged

    run = simulate_legged("stand", 0.3, seed=1)
    cols = {k: v for k, v in run.columns.items() if not k.startswith(("truth.", "contact."))}
    pd.DataFrame(cols).to_csv(path, index=False)


def _serow_go1(path: Path) -> None:
    """:func:`_go1`'s log under the names of SEROW's Go1 CSV (``Time(s)``, ``BaseWx``,
    ``JointPosFR_hip``, raw ``FR_Force`` counts: SEROW's scaling inverted)."""
    pd = pytest.importorskip("pandas")
    _go1(path)
    log = pd.read_csv(path)
    mg = 12 * 9.81  # go1_test.cpp: f = (raw + 6) m g / (m g + 24)
    names = {"t": "Time(s)"}
    names |= {f"imu.gyro.{a}": f"BaseW{a}" for a in "xyz"}
    names |= {f"imu.acc.{a}": f"BaseA{a}" for a in "xyz"}
    for leg in ("FR", "FL", "RR", "RL"):
        log[f"force.{leg}_foot"] = log[f"force.{leg}_foot"] * (mg + 24) / mg - 6
        names[f"force.{leg}_foot"] = f"{leg}_Force"
        names |= {f"q.{leg}_{p}_joint": f"JointPos{leg}_{p}" for p in ("hip", "thigh", "calf")}
    assert set(names) == set(log.columns), set(log.columns) ^ set(names)
    log.rename(columns=names).to_csv(path, index=False)


#: Files the blocks read, made in the block's folder when its code names them: the user's
#: logs, simulated (UR5, 1 kHz, σ = 1e-4 rad, seed 0, 1 s, unless said).
FIXTURES: dict[str, Callable[[Path], None]] = {
    "log.csv": _ur5_csv,
    "run.csv": _ur5_csv,
    "run.parquet": _ur5_parquet,
    "logs": _logs_folder,  # two UR5 logs, logs/a.csv and logs/b.csv
    "excitation.csv": _excitation,  # 6 s at 500 Hz
    "motors.csv": _motors,  # the drives' motor positions and currents
    "arm.csv": _arm,  # a Panda with its fingers locked, 0.5 s
    "go1.csv": _go1,
    "serow_go1.csv": _serow_go1,  # the same, under SEROW's column names
}


def _make_fixtures(code: str, folder: Path) -> None:
    for name, make in FIXTURES.items():
        if re.search(rf"""["' ]{re.escape(name)}["' \n]""", code):
            make(folder / name)


def _exec_prefix(page: str, line: str, stop: str) -> dict[str, Any]:
    """Run the part of the block of ``page`` holding ``line`` above the line ``stop``
    (the drives' definitions, so the fixture is made with the block's own numbers)."""
    block = next(b for b in blocks() if b.page == page and line in b.code)
    ns: dict[str, Any] = {"__name__": "__main__"}
    exec(compile(block.code[: block.code.index(stop)], block.id, "exec"), ns)
    return ns


# ----------------------------------------------------------------------- python blocks


def _run_python(block: Block, folder: Path, monkeypatch: pytest.MonkeyPatch) -> tuple[str, str]:
    """Run ``block`` as a script: ``(what it printed, what the docs show it prints)`` (the
    printed output itself when the docs show none)."""
    reason = (_match(NEEDS, block) or (lambda: None))()
    if reason:
        pytest.skip(reason)
    monkeypatch.chdir(folder)
    _make_fixtures(block.code, folder)
    out = io.StringIO()
    with warnings.catch_warnings(), contextlib.redirect_stdout(out):
        warnings.simplefilter("ignore")  # a user sees them printed; an old API fails:
        warnings.simplefilter("error", DeprecationWarning)
        warnings.simplefilter("error", FutureWarning)
        exec(compile(block.code, block.id, "exec"), {"__name__": "__main__"})
    shown = _output_of(block)
    return out.getvalue(), out.getvalue() if shown is None else shown.code


def _params(lang: str, slow: bool) -> list[Any]:
    """The blocks of ``lang`` run in the default run (``slow`` False) or with ``-m slow``:
    every python block; a shell block when it has a ``pinobs`` command to run (one of
    :data:`RUN`, or any when the block is slow)."""

    def runs(b: Block) -> bool:
        if lang == "python":
            return True
        return any(slow or a[1] in RUN for a in commands(b.code) if a[0] == "pinobs")

    return [
        pytest.param(b, id=b.id)
        for b in _of(lang)
        if (_match(SLOW, b) is not None) == slow and runs(b)
    ]


@pytest.mark.parametrize("block", _params("python", slow=False))
def test_python_block_runs(block: Block, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    printed, shown = _run_python(block, tmp_path, monkeypatch)
    assert printed == shown, f"{block.id} prints other than the docs show"


@pytest.mark.slow
@pytest.mark.parametrize("block", _params("python", slow=True))
def test_slow_python_block_runs(
    block: Block, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    printed, shown = _run_python(block, tmp_path, monkeypatch)
    assert printed == shown, f"{block.id} prints other than the docs show"


def _pinobs_names(tree: ast.AST) -> list[str]:
    """Dotted names the block takes from pinobs: ``from pinobs.x import y`` gives
    ``pinobs.x.y``; ``pinobs.a.b(...)`` gives ``pinobs.a.b``."""
    names: list[str] = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and (node.module or "").split(".")[0] == "pinobs":
            names += [f"{node.module}.{a.name}" for a in node.names]
        elif isinstance(node, ast.Attribute):
            parts: list[str] = []
            cur: ast.expr = node
            while isinstance(cur, ast.Attribute):
                parts.append(cur.attr)
                cur = cur.value
            if isinstance(cur, ast.Name) and cur.id == "pinobs":
                names.append(".".join(["pinobs", *reversed(parts)]))
    return names


def _resolves(dotted: str) -> bool:
    parts = dotted.split(".")
    obj: object = importlib.import_module(parts[0])
    for i, part in enumerate(parts[1:], start=1):
        if hasattr(obj, part):
            obj = getattr(obj, part)
            continue
        try:  # a submodule not imported by its package
            obj = importlib.import_module(".".join(parts[: i + 1]))
        except ImportError:
            return False
    return True


@pytest.mark.parametrize("block", [pytest.param(b, id=b.id) for b in _of("python")])
def test_python_block_parses_and_its_pinobs_names_exist(block: Block) -> None:
    """Cheap, for every block (the slow and skipped ones too): a renamed function breaks
    this test in the default run."""
    try:
        tree = ast.parse(block.code)
    except SyntaxError as exc:
        raise AssertionError(f"{block.id}: does not parse: {exc}") from exc
    missing = [n for n in _pinobs_names(tree) if not _resolves(n)]
    assert not missing, f"{block.id}: names not in pinobs: {missing}"


# ------------------------------------------------------------------------ shell blocks


def commands(code: str) -> list[list[str]]:
    """The commands of a shell block: continuations joined, comments dropped, ``&&``
    split."""
    out: list[list[str]] = []
    for line in code.replace("\\\n", " ").splitlines():
        current: list[str] = []
        for word in shlex.split(line, comments=True):
            if word == "&&":
                out.append(current)
                current = []
            else:
                current.append(word)
        if current:
            out.append(current)
    return out


def _extras() -> set[str]:
    tomllib = pytest.importorskip("tomllib")
    with (ROOT / "pyproject.toml").open("rb") as f:
        return set(tomllib.load(f)["project"]["optional-dependencies"])


def _check_pip(argv: list[str]) -> None:
    assert argv[:2] == ["pip", "install"], argv
    targets = [a for a in argv[2:] if not a.startswith("-")]
    assert targets, argv
    for target in targets:
        m = re.fullmatch(r"\.(?:\[([\w,-]+)\])?", target)
        assert m is not None, f"pip install of {target!r}: the docs install this project"
        unknown = set((m.group(1) or "").split(",")) - {""} - _extras()
        assert not unknown, f"no such extras in pyproject.toml: {sorted(unknown)}"


def _check_script(argv: list[str]) -> None:
    """``python SCRIPT args``: the script exists; each ``--flag`` is one it adds."""
    script = ROOT / argv[1]
    assert script.is_file(), f"no {argv[1]}"
    source = script.read_text()
    for flag in (a.split("=")[0] for a in argv[2:] if a.startswith("--")):
        assert re.search(rf"""add_argument\(\s*["']{flag}["']""", source), (
            f"{argv[1]} takes no {flag}"
        )


def _check_pinobs(argv: list[str], capsys: pytest.CaptureFixture[str]) -> None:
    """Parsed by ``pinobs``'s own parser, every ``--option`` spelled in full (argparse
    would take an abbreviation that a new option can make ambiguous)."""
    parser = _parser()
    try:
        parser.parse_args(argv[1:])
    except SystemExit as exc:
        raise AssertionError(f"{shlex.join(argv)}: {capsys.readouterr().err}") from exc
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    options = {o for a in sub.choices[argv[1]]._actions for o in a.option_strings}
    abbreviated = [w for w in argv[2:] if w.startswith("--") and w.split("=")[0] not in options]
    assert not abbreviated, f"{shlex.join(argv)}: spell out {abbreviated}"


@pytest.mark.parametrize("block", [pytest.param(b, id=b.id) for b in _of("bash")])
def test_shell_block_commands_exist_and_parse(
    block: Block, capsys: pytest.CaptureFixture[str]
) -> None:
    argvs = commands(block.code)
    assert argvs, block.id
    for argv in argvs:
        if argv[0] == "pinobs":
            _check_pinobs(argv, capsys)
        elif argv[0] == "pip":
            _check_pip(argv)
        elif argv[:3] == ["python", "-m", "pytest"]:
            continue  # this suite
        elif argv[0] == "python" and len(argv) > 1:
            _check_script(argv)
            assert argv[1] in NOT_RUN, f"{argv[1]}: say in NOT_RUN why it is not run"
        else:
            raise AssertionError(f"{block.id}: a command this test does not know: {argv}")


def _run_pinobs(block: Block, folder: Path, monkeypatch: pytest.MonkeyPatch) -> int:
    """Run the block's ``pinobs`` commands (each must succeed and write its ``--out``): how
    many ran."""
    monkeypatch.chdir(folder)
    _make_fixtures(block.code, folder)
    slow = _match(SLOW, block) is not None
    ran = 0
    for argv in commands(block.code):
        if argv[0] != "pinobs" or not (slow or argv[1] in RUN):
            continue
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # printed to the user as notes
            assert main(argv[1:]) == 0, shlex.join(argv)
        if "--out" in argv:
            assert (folder / argv[argv.index("--out") + 1]).exists(), shlex.join(argv)
        ran += 1
    return ran


@pytest.mark.parametrize("block", _params("bash", slow=False))
def test_shell_block_runs(block: Block, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    assert _run_pinobs(block, tmp_path, monkeypatch) > 0, f"{block.id}: no pinobs command run"


@pytest.mark.slow
@pytest.mark.parametrize("block", _params("bash", slow=True))
def test_slow_shell_block_runs(
    block: Block, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    assert _run_pinobs(block, tmp_path, monkeypatch) > 0, f"{block.id}: no pinobs command run"


def test_every_script_entry_is_a_command_of_the_docs() -> None:
    argvs = [a for b in _of("bash") for a in commands(b.code)]
    assert set(NOT_RUN) == {a[1] for a in argvs if a[0] == "python" and a[1] != "-m"}
