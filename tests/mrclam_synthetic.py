"""What the MRCLAM test modules share: the small synthetic data set and the noise models its
filters run with (the synthesizer's own noise: range 0.05 m, bearing 0.01 rad; motion close to
the synthetic robots' slip)."""

from swarmloc.agents.replay.localizers import CameraNoise, MotionNoise
from swarmloc.world.replay.mrclam import SyntheticConfig

SMALL = SyntheticConfig(n_robots=3, n_landmarks=8, duration_s=40.0)
SYNTH_CAMERA = CameraNoise(range_std_m=0.05, range_fraction=0.0, bearing_std_rad=0.01)
SYNTH_MOTION = MotionNoise(speed_fraction=0.1, speed_std_mps=0.005, turn_fraction=0.1,
                           turn_std_rad_s=0.05, turn_per_speed_rad_m=0.0)
