"""Readers: a recorded log, from any of its formats, as chunks of ``t, q, tau`` rows.

Formats (chosen from the source):

- CSV (``.csv``, ``.txt``) and TSV (``.tsv``, ``.tab``): a header row, then one
  row per sample (a file whose line 1 is all numbers has no header: its columns
  are named by position, ``"0"``, ``"1"``, ..., for ``columns`` to map, and
  :attr:`Log.notes` says so).  UTF-8 (a byte-order mark is accepted).  The columns
  are found by name (any order, extra columns ignored):

  - ``t``: time [s]; without one, a log whose rows were taken at a known fixed rate
    ``R`` (``rate=R``: FIGAROH's TX40 data, MATLAB exports) has its row ``k`` (from 0,
    across chunks; a row with an unreadable cell counts, a blank line does not) at
    ``t = k / R`` [s], said in :attr:`Log.notes`; given a ``t`` column, ``rate`` leaves it
    as it is;
  - positional ``q0 .. q{nq-1}`` and ``tau0 .. tau{nv-1}`` (Pinocchio's order,
    quaternions ``x, y, z, w``), or named ``q.<joint>`` / ``tau.<joint>``
    (``q.<joint>.<k>`` / ``tau.<joint>.<k>`` for a joint with several
    coordinates); a continuous joint (``cos, sin`` in Pinocchio) may also be
    given as one angle column ``q.<joint>`` [rad];
  - ``tick`` (optional): the logger's sample counter (ROS ``header.seq``, a
    robot's cycle count), used by the clock repair (:mod:`pinobs.io.clock`);
  - ``columns`` maps other column names to these (``{"pos_1": "q.elbow"}``,
    ``{"seq": "tick"}``).
  - with ``drives`` (:class:`~pinobs.io.Drives`): ``qm.<joint>`` motor positions and
    ``i.<joint>`` motor currents, read through gear ratios, a transmission matrix of
    coupled joints and motor constants as the joints' ``q`` and ``tau``
    (:mod:`pinobs.io.drives`); ``tau.<joint>`` scaled by ``torque_scale``.

  The torque columns are optional (every torque then reads as zero, and a
  model-based observer is warned).
  - a legged robot's ``imu.gyro.x|y|z`` [rad/s], ``imu.acc.x|y|z`` [m/s²],
    ``force.<foot frame>`` [N] or ``contact.<foot frame>`` (0/1) as
    :attr:`Log.imu_gyro`, :attr:`Log.imu_acc`, :attr:`Log.foot_force`,
    :attr:`Log.contact` (:mod:`pinobs.io.readers.legged`; a free-flyer base the
    log does not have read as NaN).
- Parquet (``.parquet``, ``.pq``): the same columns (``t``, or ``rate``).
- NPZ (``.npz``): arrays ``t`` (N,), ``q`` (N, nq), optionally ``tau`` (N, nv).
  A result saved by ``pinobs run --save`` (:meth:`pinobs.Result.save`) is read
  as the log its sensor recorded: its measurements ``q_meas`` (a NaN row: a
  dropped sample) are the log's ``q``, not its simulated truth ``q``.
- A pandas ``DataFrame``: the same columns as a CSV (``t``, or ``rate``).
- ROS bags (a rosbag2 directory with sqlite3 or MCAP storage, a ``.mcap`` or
  ``.db3`` file, a ROS 1 ``.bag``), read with the ``rosbags`` library:
  ``sensor_msgs/JointState`` messages on ``topic`` (default: the only
  JointState topic), joints matched by name in any order, ``position`` as q,
  ``effort`` as τ, the header stamp as t (the bag's receive time when the first
  message's stamp is unset, 0: said in :attr:`Log.problems`); a ROS 1 header's ``seq`` as
  the sample counter (:attr:`Log.tick`, used by the clock repair).  ``sensor_msgs/Imu`` and
  ``geometry_msgs/WrenchStamped`` topics interpolated at the JointState stamps
  (:mod:`pinobs.io.readers.bag_sensors`).

Each format has its reader (:data:`pinobs.io.readers.formats.READERS`, by suffix,
after :data:`~pinobs.io.readers.formats.DETECTORS`: a rosbag2 folder); any other
suffix is read as CSV.

A clean CSV/TSV is read by Arrow's streaming CSV reader straight into NumPy
(fast, and without importing pandas); from the first row it cannot parse as
numbers on, a careful reader takes the rest record by record and says what is
wrong with each row.  Both read standard CSV double-quoting, as the header is
read (``"moving, fast"``, ``""`` for a quote, a quoted field over several lines:
its row named by its first line); a quote that makes no such field (a stray one)
is a character of its cell, which then cannot be read.  A short row is said as
such (``row has 5 of 13 cells``); a long one is an error naming its line.

Nothing is dropped while reading: a cell that cannot be read becomes NaN and
is reported in :attr:`Log.problems` with its line (CSV) or row / message
number (the others); a file that cannot be parsed at all raises
:class:`~pinobs.errors.LogFormatError` naming the line.  CSV, TSV, Parquet and
bags are read in chunks (:func:`iter_log`), so memory does not grow with the
log; NPZ files are loaded whole.
"""

from __future__ import annotations

from pinobs.io.readers.formats import find_logs, iter_log, read_log
from pinobs.io.readers.join import join_tables
from pinobs.io.readers.log import CHUNK_ROWS, Log, LogSource, chain_chunks, concat_logs, slice_log

__all__ = [
    "CHUNK_ROWS",
    "Log",
    "LogSource",
    "chain_chunks",
    "concat_logs",
    "find_logs",
    "iter_log",
    "join_tables",
    "read_log",
    "slice_log",
]
