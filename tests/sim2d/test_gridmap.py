"""Occupancy grids: rasterisation, ROS map files, and maps turned back into geometry the LIDAR sees."""

import math
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from agri_envs.scenes import EXAMPLE_MAP
from agri_envs.scenes.greenhouse import LayoutParams, generate_layout
from agri_envs.sim2d.geometry import Geometry, GeometryBuilder, Kind
from agri_envs.sim2d.gridmap import (
    OccupancyGrid,
    grid_to_geometry,
    load_ros_map,
    occupied_rectangles,
    rasterize,
    save_ros_map,
)
from agri_envs.sim2d.raycast import footprint_clearance
from agri_envs.sim2d.sensors import Lidar, tim561


def greenhouse(growth: float = 0.5) -> Geometry:
    return generate_layout(LayoutParams(growth=growth), np.random.default_rng(0)).geometry


def inside_convex(points: np.ndarray, polygons: list[np.ndarray]) -> np.ndarray:
    """Which points lie strictly inside some counter-clockwise convex polygon."""
    hit = np.zeros(len(points), dtype=bool)
    for v in polygons:
        inside = np.ones(len(points), dtype=bool)
        for a, b in zip(v, np.roll(v, -1, axis=0), strict=True):
            inside &= (b[0] - a[0]) * (points[:, 1] - a[1]) - (b[1] - a[1]) * (points[:, 0] - a[0]) > 1e-12
        hit |= inside
    return hit


def all_cells(grid: OccupancyGrid) -> np.ndarray:
    i, j = np.meshgrid(np.arange(grid.height), np.arange(grid.width), indexing="ij")
    return np.stack([i.ravel(), j.ravel()], axis=1)


# ----------------------------------------------------------------------------------------------- grid


def test_cell_world_conversions_follow_ros_convention():
    grid = OccupancyGrid(np.zeros((4, 6), np.int8), 0.5, (1.0, -2.0, 0.0))
    # Cell (0, 0) is the lower-left one; its corner is the origin, its centre half a cell in.
    np.testing.assert_allclose(grid.cell_to_world(np.array([0, 0])), [1.25, -1.75])
    np.testing.assert_allclose(grid.cell_to_world(np.array([3, 5])), [3.75, -0.25])
    np.testing.assert_array_equal(grid.world_to_cell(np.array([[1.01, -1.99], [3.99, -0.01]])), [[0, 0], [3, 5]])
    assert grid.bounds == (1.0, -2.0, 4.0, 0.0)
    assert not grid.in_grid(grid.world_to_cell(np.array([0.9, -1.0])))
    # Round trip with a rotated origin.
    rot = OccupancyGrid(np.zeros((4, 6), np.int8), 0.5, (1.0, -2.0, 0.7))
    cells = all_cells(rot)
    np.testing.assert_array_equal(rot.world_to_cell(rot.cell_to_world(cells)), cells)


def test_grid_is_read_only_copy_and_validated():
    raw = np.zeros((2, 3), np.int16)
    grid = OccupancyGrid(raw, 0.1)
    raw[0, 0] = 100
    assert grid.data[0, 0] == 0 and grid.data.dtype == np.int8
    with pytest.raises(ValueError):
        grid.data[0, 0] = 1
    for bad in (
        dict(data=np.zeros(5, np.int8), resolution=0.1),
        dict(data=np.full((2, 2), 101), resolution=0.1),
        dict(data=np.full((2, 2), -2), resolution=0.1),
        dict(data=np.zeros((2, 2)), resolution=0.1),
        dict(data=np.zeros((2, 2), np.int8), resolution=0.0),
        dict(data=np.zeros((2, 2), np.int8), resolution=0.1, origin=(0.0, 0.0)),
    ):
        with pytest.raises(ValueError):
            OccupancyGrid(**bad)


# ------------------------------------------------------------------------------------------ rasterize


def test_rasterize_circle_area_and_cells():
    res, r = 0.05, 0.5
    b = GeometryBuilder()
    b.circle(1.0, 1.0, r, Kind.PLANT)
    grid = rasterize(b.build((0.0, 0.0, 2.0, 2.0)), res)
    assert grid.data.shape == (40, 40) and grid.origin == (0.0, 0.0, 0.0)
    assert set(np.unique(grid.data)) == {0, 100}
    area = grid.occupied_mask().sum() * res**2
    assert abs(area - math.pi * r**2) < 2 * math.pi * r * res  # within one cell's perimeter band
    occupied = grid.data[tuple(grid.world_to_cell(np.array([[1.0, 1.0], [1.0, 1.45], [1.4, 1.0]])).T)]
    free = grid.data[tuple(grid.world_to_cell(np.array([[0.1, 0.1], [1.0, 1.55], [1.4, 1.4]])).T)]
    assert np.all(occupied == 100) and np.all(free == 0)
    # Exactly the cells whose centre is within r.
    centres = grid.cell_to_world(all_cells(grid))
    expected = np.hypot(centres[:, 0] - 1.0, centres[:, 1] - 1.0) <= r
    np.testing.assert_array_equal(grid.occupied_mask().ravel(), expected)


def test_rasterize_box_capsule_and_thin_wall():
    b = GeometryBuilder()
    b.box(0.5, 0.5, 1.5, 1.0, Kind.OBSTACLE)  # aligned to cell edges: exactly 20 x 10 cells
    b.capsule(2.0, 0.5, 2.0, 1.5, 0.1, Kind.WALL)
    b.capsule(0.5, 1.725, 1.5, 1.725, 0.0, Kind.WALL)  # free-standing thin wall between cell centres
    grid = rasterize(b.build((0.0, 0.0, 2.5, 2.0)), 0.05)
    assert grid.data.shape == (40, 50)
    assert grid.data[10:20, 10:30].min() == 100
    box_region = grid.occupied_mask()[:, :35].copy()
    box_region[30:40] = False  # the thin wall's rows
    assert box_region.sum() == 200  # the box's edges do not inflate it
    capsule_cells = grid.occupied_mask()[:, 35:].sum()
    assert abs(capsule_cells * 0.05**2 - (1.0 * 0.2 + math.pi * 0.01)) < 2 * (2.0 + 2 * math.pi * 0.1) * 0.05
    assert grid.data[tuple(grid.world_to_cell(np.array([2.09, 1.0])))] == 100
    assert grid.data[tuple(grid.world_to_cell(np.array([2.12, 1.0])))] == 0
    # The thin wall is one cell thick and continuous.
    thin = grid.occupied_mask()[30:40, 10:30]
    assert thin.any(axis=0).all() and thin.sum(axis=0).max() <= 2


def test_rasterize_bounds_and_unknown_outside():
    b = GeometryBuilder()
    b.circle(0.5, 0.5, 0.2, Kind.POST)
    geometry = b.build((0.0, 0.0, 1.0, 1.0))
    grid = rasterize(geometry, 0.1, bounds=(-0.5, -0.5, 1.5, 1.5), unknown_outside=True)
    assert grid.data.shape == (20, 20) and grid.origin == (-0.5, -0.5, 0.0)
    assert grid.data[0, 0] == -1 and grid.data[5, 5] == 0 and grid.data[10, 10] == 100
    assert (grid.data == -1).sum() == 400 - 100
    # Rounding: 9.8 / 0.05 is not exactly 196 in floating point, but the grid must not grow a column.
    assert rasterize(Geometry.empty((-0.1, -0.1, 9.7, 6.1)), 0.05).data.shape == (124, 196)
    with pytest.raises(ValueError, match="resolution"):
        rasterize(geometry, 0.0)
    with pytest.raises(ValueError, match="bounds"):
        rasterize(geometry, 0.1, bounds=(1.0, 0.0, 0.0, 1.0))
    with pytest.raises(ValueError, match="too large"):
        rasterize(geometry, 1e-5, bounds=(0.0, 0.0, 1000.0, 1000.0))


# ------------------------------------------------------------------------------------------ map files


def test_save_load_round_trip(tmp_path):
    rng = np.random.default_rng(3)
    data = rng.choice(np.array([-1, 0, 100], np.int8), size=(17, 23))
    grid = OccupancyGrid(data, 0.05, (-1.5, 2.25, 0.3))
    image = save_ros_map(grid, tmp_path / "sub" / "map.yaml")
    assert image == tmp_path / "sub" / "map.pgm" and image.read_bytes().startswith(b"P5")
    loaded = load_ros_map(tmp_path / "sub" / "map.yaml")
    np.testing.assert_array_equal(loaded.data, data)
    assert loaded.resolution == 0.05 and loaded.origin == (-1.5, 2.25, 0.3)
    # The image's top row is the grid's top (highest y) row, with map_saver's grey levels.
    pixels = np.asarray(Image.open(image))
    assert pixels.shape == (17, 23)
    np.testing.assert_array_equal(pixels[0], np.select([data[-1] == 100, data[-1] == 0], [0, 254], 205))
    # A custom image name, in the YAML's folder.
    save_ros_map(grid, str(tmp_path / "other.yaml"), image_name="img.pgm")
    assert (tmp_path / "img.pgm").is_file()
    np.testing.assert_array_equal(load_ros_map(str(tmp_path / "other.yaml")).data, data)


def write_yaml(path: Path, image: str, **extra: object) -> Path:
    lines = [f"image: {image}", "resolution: 0.1", "origin: [0.0, 0.0, 0.0]"]
    lines += [f"{k}: {v}" for k, v in extra.items()]
    path.write_text("\n".join(lines) + "\n")
    return path


def test_load_honours_negate_and_thresholds(tmp_path):
    # Plain (P2) PGM with comments; values 0, 40, 128, 200, 240, 255 in one row (top) and their mirror below.
    values = [0, 40, 128, 200, 240, 255]
    text = "P2\n# handmade\n6 2\n# max\n255\n" + " ".join(map(str, values)) + "\n" + " ".join(map(str, values[::-1]))
    (tmp_path / "m.pgm").write_text(text + "\n")
    # negate 0: p = (255 - v) / 255 = 1, .84, .50, .22, .06, 0
    grid = load_ros_map(write_yaml(tmp_path / "a.yaml", "m.pgm", negate=0, occupied_thresh=0.65, free_thresh=0.196))
    np.testing.assert_array_equal(grid.data[1], [100, 100, -1, -1, 0, 0])  # image top row = grid row 1
    np.testing.assert_array_equal(grid.data[0], [0, 0, -1, -1, 100, 100])
    grid = load_ros_map(write_yaml(tmp_path / "b.yaml", "m.pgm", negate=0, occupied_thresh=0.4, free_thresh=0.1))
    np.testing.assert_array_equal(grid.data[1], [100, 100, 100, -1, 0, 0])
    # negate 1: p = v / 255 = 0, .16, .50, .78, .94, 1
    grid = load_ros_map(write_yaml(tmp_path / "c.yaml", "m.pgm", negate=1, occupied_thresh=0.65, free_thresh=0.196))
    np.testing.assert_array_equal(grid.data[1], [0, 0, -1, 100, 100, 100])
    # Defaults (negate 0, 0.65, 0.196) when the optional keys are missing.
    np.testing.assert_array_equal(
        load_ros_map(write_yaml(tmp_path / "d.yaml", "m.pgm")).data[1], [100, 100, -1, -1, 0, 0]
    )
    # scale mode puts in-between values on 0..99.
    grid = load_ros_map(write_yaml(tmp_path / "e.yaml", "m.pgm", mode="scale"))
    assert grid.data[1, 0] == 100 and grid.data[1, 5] == 0 and 0 < grid.data[1, 2] < 99


def test_load_binary_pgm_with_comment_and_png(tmp_path):
    pixels = np.array([[0, 254, 205], [254, 254, 0]], np.uint8)
    (tmp_path / "m.pgm").write_bytes(b"P5\n# CREATOR: someone\n3 2\n255\n" + pixels.tobytes())
    expected = np.array([[0, 0, 100], [100, 0, -1]], np.int8)
    np.testing.assert_array_equal(load_ros_map(write_yaml(tmp_path / "a.yaml", "m.pgm")).data, expected)
    Image.fromarray(pixels).save(tmp_path / "m.png")
    np.testing.assert_array_equal(load_ros_map(write_yaml(tmp_path / "b.yaml", "m.png")).data, expected)
    # Colour with alpha: averaged channels, transparent pixels unknown.
    rgba = np.zeros((2, 3, 4), np.uint8)
    rgba[..., :3] = pixels[..., None]
    rgba[..., 3] = 255
    rgba[1, 0, 3] = 0
    Image.fromarray(rgba).save(tmp_path / "c.png")
    colour = expected.copy()
    colour[0, 0] = -1
    np.testing.assert_array_equal(load_ros_map(write_yaml(tmp_path / "c.yaml", "c.png")).data, colour)


def test_load_bad_input_raises_value_error(tmp_path):
    (tmp_path / "ok.pgm").write_bytes(b"P5\n2 2\n255\n" + bytes([0, 254, 254, 0]))
    cases = {
        "missing_image.yaml": "resolution: 0.1\norigin: [0, 0, 0]\n",
        "missing_res.yaml": "image: ok.pgm\norigin: [0, 0, 0]\n",
        "missing_origin.yaml": "image: ok.pgm\nresolution: 0.1\n",
        "short_origin.yaml": "image: ok.pgm\nresolution: 0.1\norigin: [0, 0]\n",
        "text_res.yaml": "image: ok.pgm\nresolution: fine\norigin: [0, 0, 0]\n",
        "neg_res.yaml": "image: ok.pgm\nresolution: -0.1\norigin: [0, 0, 0]\n",
        "negate.yaml": "image: ok.pgm\nresolution: 0.1\norigin: [0, 0, 0]\nnegate: 2\n",
        "thresh.yaml": "image: ok.pgm\nresolution: 0.1\norigin: [0, 0, 0]\noccupied_thresh: 0.1\nfree_thresh: 0.5\n",
        "mode.yaml": "image: ok.pgm\nresolution: 0.1\norigin: [0, 0, 0]\nmode: fancy\n",
        "list.yaml": "- image\n- ok.pgm\n",
        "broken.yaml": "image: [ok.pgm\n",
        "no_image_file.yaml": "image: nope.pgm\nresolution: 0.1\norigin: [0, 0, 0]\n",
    }
    for name, text in cases.items():
        (tmp_path / name).write_text(text)
        with pytest.raises(ValueError):
            load_ros_map(tmp_path / name)
    with pytest.raises(ValueError, match="'origin'"):
        load_ros_map(tmp_path / "missing_origin.yaml")
    with pytest.raises(ValueError, match="does not exist"):
        load_ros_map(tmp_path / "absent.yaml")
    bad_images = {
        "magic.pgm": b"P9\n2 2\n255\n" + bytes(4),
        "truncated.pgm": b"P5\n2 2\n255\n" + bytes(3),
        "header.pgm": b"P5\n2 x\n255\n" + bytes(4),
        "ascii_short.pgm": b"P2\n2 2\n255\n0 0 0\n",
        "over_max.pgm": b"P2\n2 1\n15\n0 16\n",
        "garbage.png": b"not an image at all",
    }
    for name, content in bad_images.items():
        (tmp_path / name).write_bytes(content)
        with pytest.raises(ValueError):
            load_ros_map(write_yaml(tmp_path / f"{name}.yaml", name))
    with pytest.raises(ValueError, match=r"\.pgm"):
        save_ros_map(OccupancyGrid(np.zeros((2, 2), np.int8), 0.1), tmp_path / "x.yaml", image_name="x.png")


# ----------------------------------------------------------------------------------- back to geometry


def test_occupied_rectangles_cover_mask_exactly():
    rng = np.random.default_rng(0)
    mask = rng.random((30, 40)) < 0.4
    mask[5:15, 10:30] = True
    rects = occupied_rectangles(mask)
    cover = np.zeros(mask.shape, np.int64)
    for i0, j0, i1, j1 in rects:
        cover[i0:i1, j0:j1] += 1
    np.testing.assert_array_equal(cover, mask.astype(np.int64))  # exact and non-overlapping
    assert occupied_rectangles(np.zeros((3, 3), bool)).shape == (0, 4)
    np.testing.assert_array_equal(occupied_rectangles(np.ones((3, 4), bool)), [[0, 0, 3, 4]])


def test_grid_to_geometry_covers_occupied_cells_with_few_boxes():
    grid = rasterize(greenhouse(), 0.05)
    data = grid.data.copy()
    data[:3, :3] = -1  # unknown is free
    grid = OccupancyGrid(data, grid.resolution, grid.origin)
    geometry = grid_to_geometry(grid)
    assert geometry.bounds == pytest.approx(grid.bounds)
    assert len(geometry.circles) == 0 and len(geometry.capsules) == 4 * len(geometry.polygons)
    assert set(geometry.polygon_kinds) == {int(Kind.OBSTACLE)}
    centres = grid.cell_to_world(all_cells(grid))
    inside = inside_convex(centres, geometry.polygons)
    np.testing.assert_array_equal(inside, grid.occupied_mask().ravel())
    n_occupied = int(grid.occupied_mask().sum())
    assert len(geometry.polygons) < n_occupied / 5
    # Unknown as obstacles on request; rotated maps give rotated boxes.
    assert inside_convex(centres[:1], grid_to_geometry(grid, unknown_occupied=True).polygons)[0]
    rotated = OccupancyGrid(grid.data, grid.resolution, (1.0, 2.0, 0.4))
    rot_geometry = grid_to_geometry(rotated, Kind.WALL)
    inside = inside_convex(rotated.cell_to_world(all_cells(rotated)), rot_geometry.polygons)
    np.testing.assert_array_equal(inside, rotated.occupied_mask().ravel())


def test_lidar_in_map_geometry_matches_original(tmp_path):
    original = greenhouse(growth=0.5)
    save_ros_map(rasterize(original, 0.05), tmp_path / "gh.yaml")
    mapped = grid_to_geometry(load_ros_map(tmp_path / "gh.yaml"))
    lidar = Lidar(tim561())
    rng = np.random.default_rng(1)
    errors, hit_gaps = [], []
    x0, y0, x1, y1 = original.bounds
    while len(errors) < 10:
        pose = np.array([rng.uniform(x0, x1), rng.uniform(y0, y1), rng.uniform(-math.pi, math.pi)])
        clearance = footprint_clearance(pose[0], pose[1], pose[2], 1e-3, 1e-3, original.circles, original.capsules)
        if clearance < 0.1:
            continue
        truth = lidar.exact_scan(pose, original.circles, original.capsules).copy()
        seen = lidar.exact_scan(pose, mapped.circles, mapped.capsules).copy()
        errors.append(np.abs(seen - truth))
        # Every echo off the map's boxes comes from within a cell's half-diagonal of a real obstacle.
        angles = pose[2] + lidar.spec.beam_angles
        hit = seen < lidar.spec.max_range
        for r, a in zip(seen[hit][::10], angles[hit][::10], strict=True):
            px, py = pose[0] + r * math.cos(a), pose[1] + r * math.sin(a)
            hit_gaps.append(footprint_clearance(px, py, 0.0, 1e-6, 1e-6, original.circles, original.capsules))
    error = np.concatenate(errors)
    assert np.mean(error < 0.08) > 0.9
    assert np.median(error) < 0.01
    assert max(hit_gaps) < 0.05 * math.sqrt(0.5) + 1e-3


# ------------------------------------------------------------------------------------------ sample map


def test_example_map_loads_and_matches_a_greenhouse():
    assert EXAMPLE_MAP.is_file() and EXAMPLE_MAP.with_suffix(".pgm").stat().st_size < 100_000
    grid = load_ros_map(EXAMPLE_MAP)
    assert grid.resolution == 0.05 and set(np.unique(grid.data)) == {0, 100}
    # Closed walls all round, a free start pose, and mostly free inside.
    occ = grid.occupied_mask()
    assert occ[0].all() and occ[-1].all() and occ[:, 0].all() and occ[:, -1].all()
    layout = generate_layout(LayoutParams(), np.random.default_rng(0))
    start = grid.world_to_cell(layout.start_pose[:2])
    assert grid.in_grid(start) and grid.data[tuple(start)] == 0
    assert 0.005 < occ[2:-2, 2:-2].mean() < 0.2
