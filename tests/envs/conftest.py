"""Fixtures of the env tests."""

import pytest

from agri_envs.sim2d.world import World2D


@pytest.fixture
def contacts(monkeypatch):
    """Every contact question the single envs ask pymunk: (its answer, the exact footprint distance in m)."""
    asked = []
    touches = World2D._touches

    def recording(world, robot, pose):
        hit = touches(world, robot, pose)
        asked.append((hit, world.clearance(robot, pose)))
        return hit

    monkeypatch.setattr(World2D, "_touches", recording)
    return asked
