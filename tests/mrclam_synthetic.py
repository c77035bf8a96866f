"""What the MRCLAM test modules share: the small synthetic data set and the noise models its
filters run with (the synthesizer's own noise: range 0.05 m, bearing 0.01 rad; motion close to
the synthetic robots' slip)."""

from pathlib import Path

import numpy as np

from swarmloc.agents.replay.localizers import CameraNoise, LandmarkSetup, MotionNoise
from swarmloc.deploy.lab.replay.mrclam import ReplayConfig
from swarmloc.world.replay.mrclam import SyntheticConfig, synthesize
from swarmloc.world.replay.replay import LandmarkObservation

SMALL = SyntheticConfig(n_robots=3, n_landmarks=8, duration_s=40.0)
SYNTH_CAMERA = CameraNoise(range_std_m=0.05, range_fraction=0.0, bearing_std_rad=0.01)
SYNTH_MOTION = MotionNoise(speed_fraction=0.1, speed_std_mps=0.005, turn_fraction=0.1,
                           turn_std_rad_s=0.05, turn_per_speed_rad_m=0.0)

#: Dataset 6 where the project expects it (``../shared/data/mrclam``); tests skip without it.
DATASET6 = Path(__file__).resolve().parents[2] / "shared" / "data" / "mrclam" / "MRCLAM_Dataset6"


def synthetic_dataset():
    """The small synthetic data set every MRCLAM test module runs on (seed 11)."""
    return synthesize(SMALL, np.random.default_rng(11))


def synthetic_config(**kw) -> ReplayConfig:
    """A replay of the synthetic data set: its noise models, no camera calibration; ``kw`` are
    the other :class:`ReplayConfig` fields (``algorithm`` among them)."""
    base = {"motion": SYNTH_MOTION, "camera": SYNTH_CAMERA, "calibration": "none"}
    return ReplayConfig(**{**base, **kw})


def small_setup(**kw) -> LandmarkSetup:
    """Robot 1 with two landmarks (6 at (2, 0), 7 at (0, 2)), starting at the origin."""
    return LandmarkSetup(robot_id=1, landmark_ids=np.array([6, 7]),
                         landmark_xy_m=np.array([[2.0, 0.0], [0.0, 2.0]]),
                         initial_pose=np.zeros(3), **kw)


def empty_observation(**kw) -> LandmarkObservation:
    """Robot 1's first tick standing still with no readings, with ``kw`` replaced."""
    empty = np.zeros(0)
    base = {"robot_id": 1, "tick": 0, "time_s": 0.02, "odometry_v_mps": 0.0,
            "odometry_omega_rad_s": 0.0, "odometry_dt_s": 0.02,
            "landmark_ids": np.zeros(0, np.int64), "landmark_range_m": empty,
            "landmark_bearing_rad": empty, "robot_ids": np.zeros(0, np.int64),
            "robot_range_m": empty, "robot_bearing_rad": empty}
    return LandmarkObservation(**{**base, **kw})


#: A fan of nine landmarks 3 m from the origin at bearings within +-0.4 rad: a robot standing
#: at the origin facing +x sees them all, and a range bias ``c0 + c2 b^2`` shows at once.
FAN_RANGE_M = 3.0
FAN_BEARINGS_RAD = np.linspace(-0.4, 0.4, 9)
FAN_IDS = np.arange(10, 19)


def fan_setup(camera: CameraNoise) -> LandmarkSetup:
    """Robot 1 at the origin facing +x, the fan's landmarks around it."""
    xy = FAN_RANGE_M * np.column_stack([np.cos(FAN_BEARINGS_RAD), np.sin(FAN_BEARINGS_RAD)])
    return LandmarkSetup(robot_id=1, landmark_ids=FAN_IDS, landmark_xy_m=xy,
                         initial_pose=np.zeros(3), camera=camera)


def fan_reading(tick: int, c2: float) -> LandmarkObservation:
    """Tick ``tick`` standing at the origin: one reading of fan landmark ``tick mod 9``, its
    range biased by ``(1 + c2 b^2)``, its bearing exact."""
    j = tick % FAN_IDS.size
    bearing = FAN_BEARINGS_RAD[j:j + 1]
    return empty_observation(tick=tick, time_s=0.02 * (tick + 1), landmark_ids=FAN_IDS[j:j + 1],
                             landmark_range_m=FAN_RANGE_M * (1.0 + c2 * bearing**2),
                             landmark_bearing_rad=bearing)
