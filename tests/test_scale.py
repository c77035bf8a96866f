"""Scale on one machine (issue 20): the tiled ES3 family, the O(N) initial placement, and the
guards that refuse swarms the protocol or the machine cannot hold."""

from __future__ import annotations

import numpy as np
import pytest

from swarmloc.deploy.lab.epuck.batch import run_batch
from swarmloc.deploy.scenario import load_scenario
from swarmloc.world.epuck import kernels
from swarmloc.world.epuck.arena import area_at, arena_discs, resolve_collisions
from swarmloc.world.epuck.foraging import ForagingWorld, WorldConfig, initial_poses, tile_grid


def _initial_poses_numpy(config: WorldConfig, rng: np.random.Generator) -> np.ndarray:
    """The placement as it was written before the grid kernel (O(N^2) numpy): the reference."""
    n, radius = config.robots, config.body.body_radius_m
    centre = np.array([config.arena.width_m / 2, config.arena.height_m / 2])
    spread = config.arena.initial_radius_m
    pose = np.zeros((n, 3))
    placed = 0
    for _ in range(200):
        r = spread * np.sqrt(rng.random(n))
        a = rng.uniform(-np.pi, np.pi, n)
        cand = centre + np.stack((r * np.cos(a), r * np.sin(a)), axis=1)
        for c in cand:
            if placed == n:
                break
            if placed == 0 or np.min(np.hypot(*(pose[:placed, :2] - c).T)) >= 2 * radius:
                pose[placed, :2] = c
                placed += 1
        if placed == n:
            break
    if placed < n:
        extra = centre + rng.uniform(-spread, spread, (n - placed, 2))
        pose[placed:, :2] = extra
        pose[:, :2] = resolve_collisions(pose[:, :2], radius, config.arena.arena(), iterations=20)
    pose[:, 2] = rng.uniform(-np.pi, np.pi, n)
    return pose


@pytest.mark.parametrize("name, overrides", [
    ("ES1", []), ("ES2", []), ("ES3", []), ("SO-3.0x3.0", []),
    ("ES1", ["world.robots=30"]),  # denser than the start disc holds: the collisions' fallback
])
@pytest.mark.parametrize("seed", [1, 7])
def test_initial_poses_are_those_of_the_numpy_placement(name, overrides, seed):
    config = load_scenario(name, [*overrides, f"world.seed={seed}"]).world
    got = initial_poses(config, np.random.default_rng([seed, 0]))
    want = _initial_poses_numpy(config, np.random.default_rng([seed, 0]))
    assert np.array_equal(got, want)


def test_tile_grid_fills_tiles_and_keeps_the_arena_squarish():
    assert tile_grid(1, 6.0, 8.5) == (1, 1)
    assert tile_grid(1000, 6.0, 8.5) == (40, 25)  # 240 x 212.5 m, no tile empty
    assert tile_grid(100, 6.0, 8.5) == (10, 10)
    for tiles in (2, 3, 7, 10, 13, 97, 250):
        cols, rows = tile_grid(tiles, 6.0, 8.5)
        assert cols * rows >= tiles
        assert max(cols * 6.0, rows * 8.5) / min(cols * 6.0, rows * 8.5) <= 3.0 or cols * rows == tiles


def test_es3_tiled_keeps_es3_density_and_is_es3_at_100_robots():
    for n in (100, 1000, 10_000, 100_000):
        w = load_scenario("ES3-tiled", [f"world.robots={n}"]).world
        arena = w.arena_model()
        cols, rows = w.tiles
        assert cols * rows == -(-n // 100)
        assert n / (arena.width_m * arena.height_m) == pytest.approx(100 / (6.0 * 8.5))
    short = ["world.duration_s=30"]
    tiled = run_batch(load_scenario("ES3-tiled", short))
    es3 = run_batch(load_scenario("ES3", short))
    assert np.array_equal(tiled.final_pose, es3.final_pose)
    assert tiled.metrics == es3.metrics


def test_tiled_floor_areas_agree_between_numpy_and_the_kernels():
    arena = load_scenario("ES3-tiled", ["world.robots=1200"]).world.arena_model()
    assert arena.tile_m == (6.0, 8.5) and arena_discs(arena).shape == (8,)
    rng = np.random.default_rng(3)
    points = rng.uniform(0, 1, (20_000, 2)) * [arena.width_m, arena.height_m]
    # and points on every tile's nest and prey
    tiles = np.stack(np.meshgrid(np.arange(arena.width_m // 6), np.arange(arena.height_m // 8.5)), -1).reshape(-1, 2)
    centres = np.concatenate([tiles * [6.0, 8.5] + arena.nest.centre_m, tiles * [6.0, 8.5] + arena.prey.centre_m])
    points = np.concatenate([points, centres])
    codes = area_at(points, arena)
    assert np.array_equal(codes, kernels.area_codes(points, arena_discs(arena)))
    assert (codes[-2 * len(tiles):-len(tiles)] == 1).all() and (codes[-len(tiles):] == 2).all()


def test_tiled_world_starts_each_tile_s_robots_in_its_disc_and_forages():
    scenario = load_scenario("ES3-tiled", ["world.robots=400", "world.duration_s=2"])
    world = ForagingWorld(scenario.world)
    cols, rows = scenario.world.tiles
    assert cols * rows == 4
    for t in range(4):
        centre = np.array([(t % cols + 0.5) * 6.0, (t // cols + 0.5) * 8.5])
        xy = world.pose[t * 100:(t + 1) * 100, :2]
        assert (np.hypot(*(xy - centre).T) <= 0.5 + 1e-12).all()
    d = np.hypot(*(world.pose[:, None, :2] - world.pose[None, :, :2]).transpose(2, 0, 1))
    assert d[np.triu_indices(400, 1)].min() >= 2 * scenario.world.body.body_radius_m
    result = run_batch(scenario)
    assert result.final_pose.shape == (400, 3)


def test_batch_engine_takes_more_robots_than_the_wire_carries():
    scenario = load_scenario("ES3-tiled", ["world.robots=70000", "world.duration_s=0.2"])
    assert scenario.world.robots > 65536
    with pytest.raises(ValueError, match="robots"):
        load_scenario("ES3-tiled", [f"world.robots={2**20 + 1}"])
