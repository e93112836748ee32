"""Course generation: pure function of (map_id, seed), reachable, ten distinct maps."""

from __future__ import annotations

import dataclasses

import pytest

from game_env import NUM_MAPS, generate_course
from game_env.course import Surface
from game_env.reachability import check_course, edge_mode, is_reachable
from game_env.scene import course_xml


def test_same_map_and_seed_give_byte_identical_mjcf():
    assert course_xml(9, 5) == course_xml(9, 5)
    assert course_xml(9, 5) != course_xml(9, 6)


@pytest.mark.parametrize("map_id", range(NUM_MAPS))
def test_every_map_passes_reachability_for_20_seeds(map_id):
    for seed in range(20):
        course = generate_course(map_id, seed)
        assert check_course(course) == course.edges and is_reachable(course)
        assert len(course.edges) == len(course.surfaces) - 1


def test_maps_have_distinct_layouts():
    kinds = [frozenset(s.kind for s in generate_course(m, 0).surfaces) for m in range(NUM_MAPS)]
    assert len(set(kinds)) >= 8


def test_reachability_rejects_an_unsolvable_gap_and_generator_retries():
    course = generate_course(1, 0)
    a = course.surfaces[0]
    far = Surface("platform", a.x1 + 9.0, a.x1 + 14.0, a.z1, a.z1)
    assert edge_mode(course, a, far) is None
    broken = dataclasses.replace(course, surfaces=[a, far])
    assert check_course(broken) is None
    retried = [generate_course(1, s).attempts for s in range(20)]
    assert max(retried) > 1  # some draws of map 1 were rejected and redrawn


def test_jump_modes_follow_gap_length():
    course = generate_course(0, 0)
    a = course.surfaces[0]
    modes = [edge_mode(course, a, Surface("platform", a.x1 + g, a.x1 + g + 5, a.z1, a.z1)) for g in (0.0, 2.0, 4.0)]
    assert modes == ["walk", "jump", "sprint_jump"]
    step = Surface("platform", a.x1, a.x1 + 5, a.z1 + 0.8, a.z1 + 0.8)
    assert edge_mode(course, a, step) == "jump"


@pytest.mark.parametrize("bad", [-1, 10, None, 2.0])
def test_generate_course_rejects_bad_map_id(bad):
    with pytest.raises(ValueError, match="map_id"):
        generate_course(bad, 0)


def test_generate_course_rejects_bad_seed():
    with pytest.raises(ValueError, match="seed"):
        generate_course(0, -3)
