"""The UTIAS MRCLAM data sets: loader, and a writer of synthetic data sets in the same format.

MRCLAM (K. Y. K. Leung, Y. Halpern, T. D. Barfoot, H. H. T. Liu, "The UTIAS multi-robot
cooperative localization and mapping dataset", IJRR 30(8):969-974, 2011) records five robots
driving among 15 landmarks. Each of its nine data sets is a folder of ``.dat`` files:

- ``Barcodes.dat``: subject id, barcode number (subjects 1-5 are robots, 6-20 landmarks; the map
  differs between data sets, so each folder's own table is used);
- ``Landmark_Groundtruth.dat``: subject id, x, y [m] (Vicon), x and y std-dev [m];
- ``RobotN_Groundtruth.dat``: time [s], x, y [m], heading [rad] (Vicon; evaluation only);
- ``RobotN_Odometry.dat``: time [s], forward velocity [m/s], angular velocity [rad/s]: the logged
  velocity *commands*, about 67 Hz, held between samples (zero-order hold);
- ``RobotN_Measurement.dat``: time [s], **barcode** read by the camera, range [m], bearing [rad]
  in the body frame.

Each file opens with ``#`` header lines; columns are separated by whitespace (a TAB padded with
spaces); lines end with CRLF. :func:`load_dataset` reads any such folder and copes with the
known quirks (see ``../shared/data/mrclam/SOURCE.md``):

- CRLF (or LF) line endings, header lines anywhere, blank lines;
- measurements of barcodes that are not in ``Barcodes.dat`` (camera misreads): dropped and
  counted per robot (:attr:`RobotRecord.unknown_barcodes`);
- several measurements with one timestamp (one camera frame sees several barcodes): kept;
- rows out of time order: refused, naming the file and the line (issue 46: a stamp that goes
  back is a logging fault, and sorting it away hid which row was wrong; Dataset 6 has none, its
  equal stamps are several readings of one camera frame and are kept);
- ground truth that ends early (Dataset 6 robot 1 stops at +771.9 s) or has gaps (robot 4 has a
  2 s gap): :meth:`RobotRecord.pose_at` returns NaN where no ground truth brackets a time within
  ``max_gap_s``, so that evaluation skips those instants instead of inventing a pose.

A folder that is not a data set raises :class:`MrclamFormatError` (a ``ValueError``) naming the
missing file, or the file, line number and content of the first bad line.

Times are stored in seconds relative to :attr:`MrclamDataset.epoch_s`, the earliest ground-truth
time of the set (UNIX seconds with ms resolution do not keep sub-microsecond precision in float64
after subtraction anyway; relative times keep the arithmetic readable).

:func:`synthesize` simulates a small data set with known ground truth (unicycle robots commanded
by a wandering controller, odometry = the commands, true motion = commands with noise, a forward
camera with limited range and field of view), and :func:`write_dataset` writes any
:class:`MrclamDataset` in the published format, so that tests can exercise the loader, the replay
and the filters on data whose truth is exact. All of it is pure: no clock, no global random state.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

#: Default largest gap between two ground-truth samples across which :meth:`RobotRecord.pose_at`
#: interpolates (Dataset 6's Vicon gaps are up to 0.33 s, except one of 2.0 s for robot 4).
GROUNDTRUTH_MAX_GAP_S = 0.5

_ROBOT_FILE = re.compile(r"^Robot(\d+)_(Groundtruth|Odometry|Measurement)\.dat$")
_KINDS = ("Groundtruth", "Odometry", "Measurement")
_HEADER = "# UTIAS Multi-Robot Cooperative Localization and Mapping Dataset"


class MrclamFormatError(ValueError):
    """A folder or file is not in the MRCLAM format; the message names the file and line."""


# --------------------------------------------------------------------------------------------
# Records
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Landmarks:
    """The map: landmark subject ids ``(L,)`` and their Vicon positions ``(L, 2)`` [m]."""

    ids: np.ndarray
    xy_m: np.ndarray
    std_m: np.ndarray  #: (L, 2) Vicon std-dev of each position over the run

    def __post_init__(self):
        n = len(self.ids)
        if self.xy_m.shape != (n, 2) or self.std_m.shape != (n, 2):
            raise ValueError(f"landmarks: xy_m and std_m must have shape ({n}, 2)")
        if len(np.unique(self.ids)) != n:
            raise ValueError("landmarks: duplicate landmark ids")

    def index_of(self, ids: np.ndarray) -> np.ndarray:
        """Row of each id in :attr:`ids` (-1 for an id that is not a landmark)."""
        order = np.argsort(self.ids)
        sorted_ids = self.ids[order]
        pos = np.clip(np.searchsorted(sorted_ids, ids), 0, max(len(sorted_ids) - 1, 0))
        if len(sorted_ids) == 0:
            return np.full(np.shape(ids), -1)
        return np.where(sorted_ids[pos] == ids, order[pos], -1)


@dataclass(frozen=True)
class Measurements:
    """Range-and-bearing readings of one robot's camera, sorted by time. ``subject`` is the
    subject id (already mapped from the barcode), a landmark or a robot."""

    time_s: np.ndarray
    subject: np.ndarray
    range_m: np.ndarray
    bearing_rad: np.ndarray

    def __len__(self) -> int:
        return len(self.time_s)

    def take(self, mask: np.ndarray) -> Measurements:
        return Measurements(self.time_s[mask], self.subject[mask], self.range_m[mask],
                            self.bearing_rad[mask])


@dataclass(frozen=True)
class RobotRecord:
    """Everything recorded for one robot. Times in seconds since :attr:`MrclamDataset.epoch_s`."""

    robot_id: int
    groundtruth_time_s: np.ndarray  #: (G,)
    groundtruth_pose: np.ndarray  #: (G, 3) x_m, y_m, theta_rad (Vicon)
    odometry_time_s: np.ndarray  #: (O,)
    odometry_v_mps: np.ndarray  #: (O,) forward velocity command, held until the next sample
    odometry_omega_rad_s: np.ndarray  #: (O,) angular velocity command
    landmark_measurements: Measurements
    robot_measurements: Measurements
    #: Barcodes read by this robot's camera that ``Barcodes.dat`` does not list (dropped rows).
    unknown_barcodes: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))

    def pose_at(self, time_s: np.ndarray, max_gap_s: float = GROUNDTRUTH_MAX_GAP_S) -> np.ndarray:
        """Ground-truth poses ``(T, 3)`` at ``time_s``, linearly interpolated (heading on the
        unwrapped angle, result wrapped to ``(-pi, pi]``). NaN rows where the time lies outside
        the ground truth or inside a gap longer than ``max_gap_s``."""
        t = np.asarray(time_s, dtype=np.float64)
        gt_t, gt = self.groundtruth_time_s, self.groundtruth_pose
        out = np.full((t.size, 3), np.nan)
        if gt_t.size == 0:
            return out
        hi = np.searchsorted(gt_t, t, side="left")
        exact = (hi < gt_t.size) & (gt_t[np.minimum(hi, gt_t.size - 1)] == t)
        lo = np.clip(hi - 1, 0, gt_t.size - 1)
        hi_c = np.clip(hi, 0, gt_t.size - 1)
        inside = (hi > 0) & (hi < gt_t.size) & (gt_t[hi_c] - gt_t[lo] <= max_gap_s)
        ok = inside | exact
        theta = np.unwrap(gt[:, 2])
        out[ok, 0] = np.interp(t[ok], gt_t, gt[:, 0])
        out[ok, 1] = np.interp(t[ok], gt_t, gt[:, 1])
        out[ok, 2] = _wrap(np.interp(t[ok], gt_t, theta))
        return out


@dataclass(frozen=True)
class MrclamDataset:
    """One MRCLAM data set (or a synthetic one in the same shape)."""

    name: str
    epoch_s: float  #: UNIX time of relative time 0 (the earliest ground-truth sample)
    barcodes: dict[int, int]  #: subject id -> barcode number
    landmarks: Landmarks
    robots: dict[int, RobotRecord]  #: by robot (subject) id, in increasing id order

    @property
    def robot_ids(self) -> tuple[int, ...]:
        return tuple(self.robots)

    def time_span_s(self) -> tuple[float, float]:
        """From the latest first ground-truth sample (every robot's initial pose is known) to the
        last recorded sample of any kind."""
        start = max(float(r.groundtruth_time_s[0]) for r in self.robots.values())
        ends = []
        for r in self.robots.values():
            for t in (r.groundtruth_time_s, r.odometry_time_s, r.landmark_measurements.time_s,
                      r.robot_measurements.time_s):
                if t.size:
                    ends.append(float(t[-1]))
        return start, max(ends)


# --------------------------------------------------------------------------------------------
# Reading
# --------------------------------------------------------------------------------------------


def _wrap(angle_rad):
    """Angles wrapped to ``(-pi, pi]`` (the data set's convention)."""
    return np.pi - np.mod(np.pi - np.asarray(angle_rad, dtype=np.float64), 2.0 * np.pi)


def _scan_for_bad_line(text: str, path: Path, n_columns: int, what: str) -> None:
    """Slow path: name the first line that does not hold ``n_columns`` finite numbers."""
    for number, line in enumerate(text.splitlines(), start=1):
        stripped = line.strip()
        if not stripped or stripped.startswith("#"):
            continue
        fields = stripped.split()
        if len(fields) != n_columns:
            raise MrclamFormatError(
                f"{path.name} line {number}: expected {n_columns} columns ({what}), "
                f"got {len(fields)}: {stripped[:80]!r}")
        for column, value in enumerate(fields, start=1):
            try:
                number_value = float(value)
            except ValueError:
                raise MrclamFormatError(
                    f"{path.name} line {number} column {column}: {value!r} is not a number "
                    f"({what})") from None
            if not math.isfinite(number_value):
                raise MrclamFormatError(
                    f"{path.name} line {number} column {column}: {value!r} is not finite ({what})")


def _read_table(path: Path, n_columns: int, what: str) -> np.ndarray:
    """The numeric rows of one ``.dat`` file as ``(rows, n_columns)`` float64."""
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        raise MrclamFormatError(f"missing file {path.name} in {path.parent}") from None
    except OSError as exc:
        raise MrclamFormatError(f"cannot read {path}: {exc}") from None
    try:
        text = raw.decode("ascii")
    except UnicodeDecodeError as exc:
        raise MrclamFormatError(
            f"{path.name}: not an ASCII text file (byte {exc.start})") from None
    if "\x00" in text:
        raise MrclamFormatError(f"{path.name}: not a text file (NUL byte)")
    body = [ln for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    if not body:
        return np.zeros((0, n_columns))
    try:
        table = np.loadtxt(body, dtype=np.float64, ndmin=2)
    except ValueError:
        table = None
    if table is None or table.shape[1] != n_columns or not np.all(np.isfinite(table)):
        _scan_for_bad_line(text, path, n_columns, what)
        raise MrclamFormatError(f"{path.name}: unreadable table ({what})")  # pragma: no cover
    return table


def _refuse_repeats(values: np.ndarray, path: Path, label: str) -> None:
    """MrclamFormatError naming the first value listed twice and both data rows."""
    first: dict[int, int] = {}
    for row, value in enumerate(values.tolist(), start=1):
        if value in first:
            raise MrclamFormatError(f"{path.name}: data row {row}: {label} {value} is listed twice "
                                    f"(first at data row {first[value]})")
        first[value] = row


def _integer_column(table: np.ndarray, column: int, path: Path, what: str) -> np.ndarray:
    values = table[:, column]
    bad = np.flatnonzero(values != np.round(values))
    if bad.size:
        raise MrclamFormatError(
            f"{path.name}: data row {bad[0] + 1}: {what} must be an integer, got {values[bad[0]]}")
    return values.astype(np.int64)


def _in_time_order(table: np.ndarray, path: Path) -> np.ndarray:
    """``table`` if its times never go back, else MrclamFormatError naming the file, the line
    and both stamps (equal stamps are fine: one camera frame, several readings)."""
    back = np.flatnonzero(np.diff(table[:, 0]) < 0) if table.shape[0] > 1 else ()
    if len(back):
        row = int(back[0]) + 1  # the data row (0-based) whose stamp is earlier than the one before
        lines = [n for n, ln in enumerate(path.read_text(encoding="ascii").splitlines(), start=1)
                 if ln.strip() and not ln.lstrip().startswith("#")]
        raise MrclamFormatError(
            f"{path.name} line {lines[row]}: time {float(table[row, 0])!r} goes back from {float(table[row - 1, 0])!r} "
            f"(line {lines[row - 1]}): stamps must not decrease")
    return table


def _robot_files(folder: Path) -> dict[int, set[str]]:
    found: dict[int, set[str]] = {}
    for entry in folder.iterdir():
        match = _ROBOT_FILE.match(entry.name)
        if match:
            found.setdefault(int(match.group(1)), set()).add(match.group(2))
    return found


def load_dataset(folder: str | Path, name: str | None = None) -> MrclamDataset:
    """Read one MRCLAM data set folder (see the module docstring for the format and quirks), or
    a rosbag2 folder in the layout of :mod:`swarmloc.world.replay.rosbag`.

    Raises :class:`MrclamFormatError` naming the missing file or the first bad line.
    """
    folder = Path(folder)
    if not folder.exists():
        raise MrclamFormatError(f"no such folder: {folder}")
    if (folder / "metadata.yaml").is_file():  # a ROS 2 bag of one's own robots (issue 44)
        from swarmloc.world.replay.rosbag import read_rosbag2

        return read_rosbag2(folder, name)
    if not folder.is_dir():
        raise MrclamFormatError(f"not a folder: {folder} (give the data set folder of .dat files)")
    for required in ("Barcodes.dat", "Landmark_Groundtruth.dat"):
        if not (folder / required).is_file():
            raise MrclamFormatError(
                f"{folder} is not an MRCLAM data set: missing file {required}")
    robot_files = _robot_files(folder)
    if not robot_files:
        raise MrclamFormatError(
            f"{folder} is not an MRCLAM data set: missing file Robot1_Groundtruth.dat "
            "(no RobotN_*.dat files)")
    for robot_id, kinds in sorted(robot_files.items()):
        for kind in _KINDS:
            if kind not in kinds:
                raise MrclamFormatError(
                    f"{folder} is not a complete MRCLAM data set: missing file "
                    f"Robot{robot_id}_{kind}.dat")

    path = folder / "Barcodes.dat"
    table = _read_table(path, 2, "subject id, barcode")
    subjects = _integer_column(table, 0, path, "subject id")
    codes = _integer_column(table, 1, path, "barcode")
    for values, label in ((subjects, "subject id"), (codes, "barcode")):
        _refuse_repeats(values, path, label)
    barcodes = {int(s): int(c) for s, c in zip(subjects, codes)}
    subject_of_barcode = {c: s for s, c in barcodes.items()}

    path = folder / "Landmark_Groundtruth.dat"
    table = _read_table(path, 5, "subject id, x, y, x std-dev, y std-dev")
    landmark_ids = _integer_column(table, 0, path, "subject id")
    _refuse_repeats(landmark_ids, path, "landmark subject id")
    landmarks = Landmarks(landmark_ids, table[:, 1:3].copy(), table[:, 3:5].copy())
    clash = set(landmark_ids.tolist()) & set(robot_files)
    if clash:
        raise MrclamFormatError(
            f"{path.name}: subject {min(clash)} is both a landmark and a robot (Robot{min(clash)}_*)")
    # A robot of Barcodes.dat (a subject that is not a landmark) without its files: a data set
    # with a robot missing (the robots' ids are 1..N in every MRCLAM data set).
    missing_robots = sorted(set(barcodes) - set(landmark_ids.tolist()) - set(robot_files))
    if missing_robots:
        raise MrclamFormatError(
            f"{folder} is not a complete MRCLAM data set: missing file "
            f"Robot{missing_robots[0]}_Groundtruth.dat (robot {missing_robots[0]} is in "
            f"Barcodes.dat)")

    raw: dict[int, dict[str, np.ndarray]] = {}
    for robot_id in sorted(robot_files):
        raw[robot_id] = {
            kind: _in_time_order(_read_table(folder / f"Robot{robot_id}_{name}.dat", n, what),
                                 folder / f"Robot{robot_id}_{name}.dat")
            for kind, name, n, what in (("gt", "Groundtruth", 4, "time, x, y, orientation"),
                                        ("odo", "Odometry", 3, "time, forward velocity, angular velocity"),
                                        ("meas", "Measurement", 4, "time, barcode, range, bearing"))
        }
        if raw[robot_id]["gt"].shape[0] == 0:
            raise MrclamFormatError(
                f"Robot{robot_id}_Groundtruth.dat has no data rows (the initial pose comes from it)")
        if raw[robot_id]["odo"].shape[0] == 0:
            raise MrclamFormatError(
                f"Robot{robot_id}_Odometry.dat has no data rows (the robot's motion comes from it)")
    epoch = min(float(r["gt"][0, 0]) for r in raw.values())

    landmark_set = set(landmark_ids.tolist())
    robot_set = set(robot_files)
    robots: dict[int, RobotRecord] = {}
    for robot_id, r in raw.items():
        meas_path = folder / f"Robot{robot_id}_Measurement.dat"
        meas = r["meas"]
        codes = _integer_column(meas, 1, meas_path, "barcode")
        bad_range = np.flatnonzero(meas[:, 2] < 0.0)
        if bad_range.size:
            raise MrclamFormatError(
                f"{meas_path.name}: data row {bad_range[0] + 1}: negative range {meas[bad_range[0], 2]}")
        subject = np.array([subject_of_barcode.get(int(c), -1) for c in codes], dtype=np.int64) \
            if codes.size else np.zeros(0, np.int64)
        known = subject >= 0
        is_landmark = np.isin(subject, list(landmark_set))
        is_robot = np.isin(subject, list(robot_set - {robot_id}))
        all_meas = Measurements(meas[:, 0] - epoch, subject, meas[:, 2].copy(), meas[:, 3].copy())
        robots[robot_id] = RobotRecord(
            robot_id=robot_id,
            groundtruth_time_s=r["gt"][:, 0] - epoch,
            groundtruth_pose=np.column_stack([r["gt"][:, 1:3], _wrap(r["gt"][:, 3])]),
            odometry_time_s=r["odo"][:, 0] - epoch,
            odometry_v_mps=r["odo"][:, 1].copy(),
            odometry_omega_rad_s=r["odo"][:, 2].copy(),
            landmark_measurements=all_meas.take(is_landmark),
            robot_measurements=all_meas.take(is_robot),
            unknown_barcodes=codes[~known],
        )
    return MrclamDataset(name=name or folder.name, epoch_s=epoch, barcodes=barcodes,
                         landmarks=landmarks, robots=robots)


# --------------------------------------------------------------------------------------------
# Writing
# --------------------------------------------------------------------------------------------

_FORMAT_LINE = {
    "Barcodes": "# Subject #    Barcode #",
    "Landmark_Groundtruth": "# Subject #    x [m]    y [m]    x std-dev [m]    y std-dev [m] ",
    "Groundtruth": "# Time [s]    x [m]    y [m]    orientation [rad] ",
    "Odometry": "# Time [s]    forward velocity [m/s]    angular velocity[rad/s] ",
    "Measurement": "# Time [s]    Subject #    range [m]    bearing [rad] ",
}
_TITLE = {
    "Barcodes": "Barcode", "Landmark_Groundtruth": "Landmark Groundtruth",
    "Groundtruth": "Robot Groundtruth", "Odometry": "Odometry", "Measurement": "Measurement",
}


def _write_table(path: Path, kind: str, columns: list[tuple[np.ndarray, str]]) -> None:
    """One file in the published layout: 4 header lines, ``value \\t value`` rows, CRLF."""
    header = [_HEADER, "# produced by swarmloc.world.replay.mrclam.write_dataset (synthetic)",
              f"# {_TITLE[kind]} Data Fomat:", _FORMAT_LINE[kind]]
    n = len(columns[0][0]) if columns else 0
    parts = [[fmt.format(v) for v in values] for values, fmt in columns]
    rows = [" \t ".join(p[i] for p in parts) + " " for i in range(n)]
    path.write_bytes(("\r\n".join(header + rows) + "\r\n").encode("ascii"))


def write_dataset(dataset: MrclamDataset, folder: str | Path, *,
                  unknown_barcode_rows: dict[int, list[tuple[float, int, float, float]]] | None = None,
                  ) -> Path:
    """Write ``dataset`` as a folder of MRCLAM ``.dat`` files (CRLF, 4 header lines, TAB-padded
    columns, ms time resolution, absolute times = ``epoch_s`` + relative times).

    ``unknown_barcode_rows`` adds measurement rows ``(time_s, barcode, range_m, bearing_rad)``
    per robot with barcodes that the table does not list, as the real data has.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    subjects = np.array(sorted(dataset.barcodes), dtype=np.int64)
    _write_table(folder / "Barcodes.dat", "Barcodes", [
        (subjects, "{:3d}"), (np.array([dataset.barcodes[s] for s in subjects]), "{:3d}")])
    lm = dataset.landmarks
    _write_table(folder / "Landmark_Groundtruth.dat", "Landmark_Groundtruth", [
        (lm.ids, "{:3d}"), (lm.xy_m[:, 0], "{:.8f}"), (lm.xy_m[:, 1], "{:.8f}"),
        (lm.std_m[:, 0], "{:.8f}"), (lm.std_m[:, 1], "{:.8f}")])
    extra = unknown_barcode_rows or {}
    for robot_id, rec in dataset.robots.items():
        t0 = dataset.epoch_s
        _write_table(folder / f"Robot{robot_id}_Groundtruth.dat", "Groundtruth", [
            (rec.groundtruth_time_s + t0, "{:.3f}"), (rec.groundtruth_pose[:, 0], "{:.8f}"),
            (rec.groundtruth_pose[:, 1], "{:.8f}"), (rec.groundtruth_pose[:, 2], "{:.8f}")])
        _write_table(folder / f"Robot{robot_id}_Odometry.dat", "Odometry", [
            (rec.odometry_time_s + t0, "{:.3f}"), (rec.odometry_v_mps, "{:6.3f}"),
            (rec.odometry_omega_rad_s, "{:6.3f}")])
        meas = [rec.landmark_measurements, rec.robot_measurements]
        time_s = np.concatenate([m.time_s for m in meas])
        code = np.array([dataset.barcodes[int(s)] for m in meas for s in m.subject], dtype=np.int64)
        range_m = np.concatenate([m.range_m for m in meas])
        bearing = np.concatenate([m.bearing_rad for m in meas])
        rows = extra.get(robot_id, [])
        if rows:
            arr = np.array(rows, dtype=np.float64).reshape(-1, 4)
            time_s = np.concatenate([time_s, arr[:, 0]])
            code = np.concatenate([code, arr[:, 1].astype(np.int64)])
            range_m = np.concatenate([range_m, arr[:, 2]])
            bearing = np.concatenate([bearing, arr[:, 3]])
        order = np.argsort(time_s, kind="stable")
        _write_table(folder / f"Robot{robot_id}_Measurement.dat", "Measurement", [
            (time_s[order] + t0, "{:.3f}"), (code[order], "{:4d}"),
            (range_m[order], "{:6.3f}"), (bearing[order], "{:6.3f}")])
    return folder


# --------------------------------------------------------------------------------------------
# Synthetic data sets
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class SyntheticConfig:
    """A small simulated MRCLAM-like run. Defaults: three robots for 60 s among 8 landmarks in a
    4 x 4 m area, with MRCLAM's speeds and noise magnitudes scaled down so tests run fast."""

    n_robots: int = 3
    n_landmarks: int = 8
    duration_s: float = 60.0
    area_m: float = 4.0  #: robots wander in [0, area]^2; landmarks lie on its border
    groundtruth_rate_hz: float = 100.0
    odometry_rate_hz: float = 50.0
    camera_rate_hz: float = 5.0
    camera_max_range_m: float = 5.0
    camera_fov_rad: float = 1.2  #: full field of view of the forward camera
    range_std_m: float = 0.05
    bearing_std_rad: float = 0.01
    speed_mps: float = 0.08
    max_turn_rate_rad_s: float = 0.5
    #: Odometry error, as on MRCLAM mostly systematic: each robot's true speed is its command
    #: times ``1 + e_v`` and its true turn rate the command plus ``e_w``, with ``e_v`` and
    #: ``e_w`` drawn once per robot (std ``speed_noise_fraction`` and ``turn_rate_noise_rad_s``),
    #: plus white noise of the same stds on every odometry sample.
    speed_noise_fraction: float = 0.1
    turn_rate_noise_rad_s: float = 0.05
    #: Robots whose camera never reports a landmark (it still sees robots).
    blind_robots: tuple[int, ...] = ()
    #: Bearing-dependent range bias, as MRCLAM's cameras have: measured = true (1 + c0 + c2 b^2).
    range_bias_c0: float = 0.0
    range_bias_c2: float = 0.0
    epoch_s: float = 1.6e9

    def __post_init__(self):
        for name in ("n_robots", "n_landmarks"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"{name} must be an integer >= 1, got {value!r}")
        for name in ("duration_s", "area_m", "groundtruth_rate_hz", "odometry_rate_hz",
                     "camera_rate_hz", "camera_max_range_m", "camera_fov_rad", "speed_mps",
                     "max_turn_rate_rad_s"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a finite number > 0, got {value!r}")
        for name in ("range_std_m", "bearing_std_rad", "speed_noise_fraction",
                     "turn_rate_noise_rad_s"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
                raise ValueError(f"{name} must be a finite number >= 0, got {value!r}")
        for name in ("range_bias_c0", "range_bias_c2"):
            if not math.isfinite(getattr(self, name)):
                raise ValueError(f"{name} must be finite, got {getattr(self, name)!r}")
        for robot_id in self.blind_robots:
            if not 1 <= robot_id <= self.n_robots:
                raise ValueError(f"blind_robots: no robot {robot_id} (robots are 1..{self.n_robots})")


def synthesize(config: SyntheticConfig, rng: np.random.Generator) -> MrclamDataset:
    """Simulate a run and return it as a data set with exact ground truth.

    The simulation integrates unicycles at the ground-truth rate. Each robot's command
    ``(v, omega)`` is resampled at the odometry rate (wander: random turn rate; steer back to the
    area's centre when near its border); the logged odometry is the command, the true motion is
    the command with a per-robot speed scale error and turn-rate bias plus white noise (see
    :class:`SyntheticConfig`; dead reckoning drifts as on MRCLAM). At the camera rate every robot reads the range and bearing (Gaussian
    noise) of every landmark and robot within range and field of view.
    Subject ids: robots 1..n, landmarks n+1..n+L (as in MRCLAM, robots come first).
    """
    c = config
    n, n_lm = c.n_robots, c.n_landmarks
    robot_ids = np.arange(1, n + 1)
    landmark_ids = np.arange(n + 1, n + n_lm + 1)
    # Landmarks evenly spread on the border of a square 0.5 m outside the area.
    s = np.arange(n_lm) / n_lm * 4.0
    side, frac = np.floor(s).astype(int), s - np.floor(s)
    lo, hi = -0.5, c.area_m + 0.5
    span = hi - lo
    corners = np.array([[lo, lo], [hi, lo], [hi, hi], [lo, hi], [lo, lo]])
    landmark_xy = corners[side] + (corners[side + 1] - corners[side]) * frac[:, None]
    landmark_xy = landmark_xy + rng.normal(0.0, 0.05 * span / 4, size=landmark_xy.shape)
    landmark_xy = np.round(landmark_xy, 8)

    dt = 1.0 / c.groundtruth_rate_hz
    n_steps = round(c.duration_s * c.groundtruth_rate_hz)
    odo_every = max(1, round(c.groundtruth_rate_hz / c.odometry_rate_hz))
    cam_every = max(1, round(c.groundtruth_rate_hz / c.camera_rate_hz))
    pose = np.column_stack([rng.uniform(0.2 * c.area_m, 0.8 * c.area_m, size=(n, 2)),
                            rng.uniform(-np.pi, np.pi, size=n)])
    centre = np.full(2, c.area_m / 2.0)
    speed_scale = 1.0 + c.speed_noise_fraction * rng.standard_normal(n)
    turn_bias = c.turn_rate_noise_rad_s * rng.standard_normal(n)

    gt_t, gt_pose = [], []
    odo_t, odo_cmd = [], []
    meas = {rid: [] for rid in robot_ids}
    cmd = np.zeros((n, 2))
    true_vel = np.zeros((n, 2))
    for k in range(n_steps + 1):
        t = k * dt
        gt_t.append(t)
        gt_pose.append(pose.copy())
        if k % cam_every == 0 and k > 0:
            _camera(c, rng, t, pose, robot_ids, landmark_ids, landmark_xy, meas)
        if k == n_steps:
            break
        if k % odo_every == 0:
            to_centre = centre - pose[:, :2]
            heading_err = _wrap(np.arctan2(to_centre[:, 1], to_centre[:, 0]) - pose[:, 2])
            near_border = np.linalg.norm(to_centre, axis=1) > 0.4 * c.area_m
            wander = rng.uniform(-c.max_turn_rate_rad_s, c.max_turn_rate_rad_s, size=n)
            steer = np.clip(1.5 * heading_err, -c.max_turn_rate_rad_s, c.max_turn_rate_rad_s)
            # The logged commands have MRCLAM's 3-decimal resolution.
            cmd = np.round(np.column_stack([np.full(n, c.speed_mps),
                                            np.where(near_border, steer, wander)]), 3)
            odo_t.append(t)
            odo_cmd.append(cmd.copy())
            true_vel = np.column_stack([
                cmd[:, 0] * (speed_scale + c.speed_noise_fraction * rng.standard_normal(n)),
                cmd[:, 1] + turn_bias + c.turn_rate_noise_rad_s * rng.standard_normal(n)])
        half = pose[:, 2] + true_vel[:, 1] * dt / 2.0
        pose = pose + np.column_stack([true_vel[:, 0] * dt * np.cos(half),
                                       true_vel[:, 0] * dt * np.sin(half), true_vel[:, 1] * dt])
        pose[:, 2] = _wrap(pose[:, 2])

    gt_t = np.round(np.asarray(gt_t), 3)
    gt_pose = np.round(np.asarray(gt_pose), 8)
    odo_t = np.round(np.asarray(odo_t), 3)
    odo_cmd = np.asarray(odo_cmd)
    robots: dict[int, RobotRecord] = {}
    for i, rid in enumerate(robot_ids):
        rows = np.array(meas[rid], dtype=np.float64).reshape(-1, 4)
        all_meas = Measurements(np.round(rows[:, 0], 3), rows[:, 1].astype(np.int64),
                                np.round(rows[:, 2], 3), np.round(rows[:, 3], 3))
        is_lm = np.isin(all_meas.subject, landmark_ids)
        if int(rid) in c.blind_robots:
            is_lm = np.zeros_like(is_lm)
        robots[int(rid)] = RobotRecord(
            robot_id=int(rid),
            groundtruth_time_s=gt_t, groundtruth_pose=gt_pose[:, i, :],
            odometry_time_s=odo_t, odometry_v_mps=odo_cmd[:, i, 0],
            odometry_omega_rad_s=odo_cmd[:, i, 1],
            landmark_measurements=all_meas.take(is_lm),
            robot_measurements=all_meas.take(np.isin(all_meas.subject, robot_ids)),
        )
    # Barcodes: distinct two-digit numbers, as in MRCLAM.
    codes = rng.choice(np.arange(5, 96), size=n + n_lm, replace=False)
    barcodes = {int(sid): int(code) for sid, code in
                zip(np.concatenate([robot_ids, landmark_ids]), codes)}
    return MrclamDataset(
        name="synthetic", epoch_s=float(c.epoch_s), barcodes=barcodes,
        landmarks=Landmarks(landmark_ids, landmark_xy, np.full((n_lm, 2), 1e-4)),
        robots=robots)


def _camera(c: SyntheticConfig, rng, t, pose, robot_ids, landmark_ids, landmark_xy, meas) -> None:
    """One camera frame of every robot: range and bearing of every subject in view."""
    n = pose.shape[0]
    targets_xy = np.concatenate([pose[:, :2], landmark_xy])
    target_ids = np.concatenate([robot_ids, landmark_ids])
    d = targets_xy[None, :, :] - pose[:, None, :2]  # (n, targets, 2)
    rng_m = np.linalg.norm(d, axis=2)
    bearing = _wrap(np.arctan2(d[..., 1], d[..., 0]) - pose[:, 2:3])
    visible = (rng_m > 1e-6) & (rng_m <= c.camera_max_range_m) & \
        (np.abs(bearing) <= c.camera_fov_rad / 2.0)
    noise = rng.standard_normal((n, len(target_ids), 2))
    bias = 1.0 + c.range_bias_c0 + c.range_bias_c2 * bearing * bearing
    noisy_range = np.maximum(0.0, rng_m * bias + c.range_std_m * noise[..., 0])
    noisy_bearing = _wrap(bearing + c.bearing_std_rad * noise[..., 1])
    for i in range(n):
        seen = np.flatnonzero(visible[i])
        meas[robot_ids[i]].extend(zip(np.full(seen.size, t), target_ids[seen],
                                      noisy_range[i, seen], noisy_bearing[i, seen]))
